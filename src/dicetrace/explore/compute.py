"""The explorer's work: outcome maps of views, one throw's details, saved scans — off the server's event loop.

Maps are computed a strip of image rows at a time (see
:mod:`dicetrace.explore.outcome_map`) on one worker thread (numba's parallel
regions use the cores inside it); a map being computed can be read as far as
it is (:meth:`Worker.progress`).  A refined map takes the results of the grid
points it shares with the view's coarser passes.  The worker's thread serves every map in the making in turn, a
kernel call of about ``CHUNK_S`` seconds each, so one client's slow map cannot
hold up another's; each map has a budget of computing time
(:class:`OverBudget`).  Every map request carries a client id: a newer request
from the same client supersedes the older one, which fails at once with
:class:`Cancelled`.  Finished maps are cached by view, up to ``CACHE_BYTES``.
The maps and saved scans run on the worker's device (the CPU, or a CUDA GPU:
``Worker(device=...)``, one kernel call at a time); a hover's and the viewer's
single throws run on the CPU.
"""

from __future__ import annotations

import contextlib
import queue
import re
import threading
import time
from collections import OrderedDict, deque
from concurrent.futures import Future, InvalidStateError
from dataclasses import replace
from pathlib import Path

import numpy as np

from dicetrace.body_text import die_text, fmt_num
from dicetrace.devices import resolve_device
from dicetrace.explore.outcome_map import Cancelled, MapBuild, OutcomeMap
from dicetrace.explore.view import View, ViewError

#: Bytes of finished maps the cache keeps, all clients together (a 1024² map is 10 MiB, a 256² one 0.6 MiB).
CACHE_BYTES = 160 * 2**20
#: Seconds of computing one map may take (its own kernel calls; :class:`OverBudget` past it).
MAP_BUDGET_S = 60.0
#: A map whose rate so far says it would take more than this many budgets is refused at once.
BUDGET_SLACK = 4.0
#: Seconds a kernel call of a map should take, about: how long another client's map, a newer view or
#: a cancel waits at most (beyond one throw per numba thread, which no call can be shorter than).
CHUNK_S = 0.2
#: Maps in the making at once, all clients together (more is refused as busy).
MAX_JOBS = 32
#: Hovers and viewer throws waiting for one of their two threads, all clients together (more: :class:`Busy`).
MAX_THROWS_WAITING = 16
#: Saves waiting for the save thread, all clients together (more: :class:`Busy`).  Each save's view has passed the
#: map budget first (its map computed, or the cache's), so a save takes about a map's computing at most.
MAX_SAVES_WAITING = 2
#: Threads that compute maps.  One computes while the pieces are short; when every running piece has run
#: longer than ``STUCK_S`` (a throw of a tiny dt can take minutes, and no kernel call can be cut), the next
#: lane takes the next map, so clients with slow maps hold up at most this many minus one lanes.
MAX_LANES = 3
#: Seconds after which a running piece counts as stuck (another lane may start), s.
STUCK_S = 1.0
#: A saved scan's name.
SCAN_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$")


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
    from dicetrace.simulate import simulate  # lazy: imports numba; `import dicetrace.explore` does not

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
        "die": die_text(cfg.preset),
    }


def throw_name(view: View, coords) -> str:
    """File stem of a throw, as ``dicetrace record`` names one given on a slice (``seed_x1.65_y3.9``)."""
    parts = [view.slice] + [f"{a}{c!r}" for a, c in zip("xyz", coords)]
    if view.preset != "seed":
        parts.append(view.preset)
    if view.die is not None:
        parts.append("die" + "x".join(fmt_num(v) for v in view.die))
    if view.load is not None:
        parts.append("load" + fmt_num(view.load[0]) + "at" + ",".join(fmt_num(v) for v in view.load[1:]))
    return "_".join(parts)


def check_recording(view: View, n_throws: int = 1) -> None:
    """Refuse (:class:`ViewError` naming ``dt``), before anything runs, ``n_throws`` recorded throws of ``view``'s
    configuration that ``dicetrace record`` would refuse: their recording may need more memory than is available
    (:func:`dicetrace.sinks.rerun.recording_memory`: throws that run to the time cap)."""
    from dicetrace.sinks._common import human_bytes
    from dicetrace.sinks.rerun import recording_memory  # lazy: `import dicetrace.explore` does not load rerun

    cfg = view.config()
    steps, need, avail = recording_memory(cfg, n_throws)
    if avail is not None and need > avail:
        what = "a throw" if n_throws == 1 else f"{n_throws} throws"
        raise ViewError("dt", f"at dt {cfg.numerics.dt_s:g} s {what} may run to the time cap of "
                              f"{cfg.numerics.t_max_s:g} s, {steps:,} steps, whose recording needs up to "
                              f"{human_bytes(need)} of memory, more than the {human_bytes(avail)} available "
                              "(as dicetrace record refuses it): choose a longer time step (dt)")


def throw_aspect(text) -> float | None:
    """The ``aspect`` query parameter (the width/height of the viewer's 3-D view, which its camera frames for;
    absent: None, the recording's default) as a float, or :class:`ViewError` naming ``aspect``."""
    if text is None or text == "":
        return None
    from dicetrace.sinks.rerun_view import check_aspect  # lazy: `import dicetrace.explore` does not load scipy

    try:
        return check_aspect(str(text)[:40])
    except ValueError as e:
        raise ViewError("aspect", str(e).removeprefix("aspect ")) from None


def throw_rrd(view: View, i: int, j: int, activate: bool = False, aspect: float | None = None) -> tuple[str, bytes, dict]:
    """The Rerun recording of grid point (i, j), made as ``dicetrace record`` makes one: (name, bytes, summary).

    ``activate``: record's blueprint is also made the active one, for Rerun's web viewer
    (:func:`dicetrace.sinks.rerun.encode_rrd`); ``aspect``: the width/height of the 3-D view its camera frames
    for (None: the recording's default, :data:`dicetrace.sinks.rerun_view.VIEW_ASPECT`).
    """
    from dicetrace.simulate import Record, simulate  # lazy: imports numba; `import dicetrace.explore` does not
    from dicetrace.sinks.rerun import encode_rrd_of

    coords, ic = point_ic(view, i, j)
    roll = simulate(ic, config=view.config(), record=Record(states=True, energy=True))
    name = throw_name(view, coords)
    label = f"{view.slice} slice at " + ", ".join(f"{a} = {c!r}" for a, c in zip("xyz", coords))
    data = encode_rrd_of(roll, name=name, ic_label=label, activate=activate, aspect=aspect)
    return name, data, {"outcome": roll.outcome, "status": roll.status.label, "steps": roll.steps}


class OverBudget(Exception):
    """A map would take more computing than the worker's budget per map (``param``: the view parameter to change)."""

    param = "res"


class Busy(Exception):
    """The worker holds as many maps in the making (:data:`MAX_JOBS`), or throws waiting
    (:data:`MAX_THROWS_WAITING`), as it may."""

    param = None


class _DaemonPool:
    """A few daemon threads running submitted calls (futures): unlike ThreadPoolExecutor's, nobody waits for
    them when the interpreter exits, so a throw or a save in progress does not keep a stopped server alive."""

    def __init__(self, n: int, name: str, max_waiting: int | None = None, what: str = "calls"):
        self._q: "queue.SimpleQueue" = queue.SimpleQueue()
        self._stopped = False
        self._max_waiting = max_waiting
        self._what = what
        self._waiting = 0
        self._count_lock = threading.Lock()
        self._futures: set = set()  # submitted and not settled: failed at once by cancel_all
        for k in range(n):
            threading.Thread(target=self._run, name=f"{name}-{k}", daemon=True).start()

    def _run(self) -> None:
        while True:
            item = self._q.get()
            if item is None:
                return
            fut, fn, args = item
            with self._count_lock:
                self._waiting -= 1
            try:  # False: cancelled while it waited; done (or RuntimeError, in a race): failed by cancel_all
                run = not fut.done() and fut.set_running_or_notify_cancel()
            except RuntimeError:
                run = False
            if not run:
                self._settled(fut)
                continue
            try:
                result = fn(*args)
            except BaseException as e:
                with contextlib.suppress(InvalidStateError):  # failed already by cancel_all
                    fut.set_exception(e)
            else:
                with contextlib.suppress(InvalidStateError):
                    fut.set_result(result)
            self._settled(fut)

    def _settled(self, fut: Future) -> None:
        with self._count_lock:
            self._futures.discard(fut)

    def check_room(self) -> None:
        """:class:`Busy` when as many calls wait as may."""
        with self._count_lock:
            if self._max_waiting is not None and self._waiting >= self._max_waiting:
                raise Busy(f"{self._waiting} {self._what} are waiting already (at most {self._max_waiting}): "
                           "try again in a moment")

    def submit(self, fn, *args) -> Future:
        fut: Future = Future()
        if self._stopped:
            fut.set_exception(Cancelled("the explorer is stopping"))
            return fut
        self.check_room()
        with self._count_lock:
            self._waiting += 1
            self._futures.add(fut)
        self._q.put((fut, fn, args))
        return fut

    def cancel_all(self) -> None:
        """Every call submitted and not settled fails with :class:`Cancelled` now, so whoever waits for it answers
        at once; a call being run ends on its own thread, its result dropped."""
        with self._count_lock:
            futures, self._futures = list(self._futures), set()
        for fut in futures:
            with contextlib.suppress(InvalidStateError):
                fut.set_exception(Cancelled("the explorer is stopping"))

    def shutdown(self, n: int) -> None:
        self._stopped = True
        for _ in range(n):
            self._q.put(None)


class _Job:
    """One map in the making: the clients waiting for it, its future, its budget's account."""

    def __init__(self, view: View):
        self.view, self.key = view, view.key()
        self.clients: set = set()
        self.future: Future = Future()
        self.cancelled = False
        self.build: MapBuild | None = None  # made on its first turn (on the worker's thread)
        self.spent_s = 0.0  # computing time of its own pieces (but the first)
        self.counted: int | None = None  # ICs thrown in those pieces (None: the first piece is still to come)
        self.chunk = 0  # ICs of its next step (0: not sized yet)


def map_nbytes(m: OutcomeMap) -> int:
    """Bytes of a map's arrays."""
    return int(sum(a.nbytes for a in (m.outcome, m.steps, m.status, m.xs, m.ys)))


class Worker:
    """Makes maps for many clients a piece at a time, in turn; throws and saves on threads of their own.

    Every map in the making is a job; the worker's thread gives each job in
    turn one kernel call of about ``CHUNK_S`` seconds (sized from the job's
    own rate so far, one IC per numba thread at first), so a small map of one
    client is done after at most one piece of another's big one; a piece that
    runs longer than ``STUCK_S`` (one throw of a tiny dt can take minutes) lets
    another of ``MAX_LANES`` threads take the next job meanwhile.  A client's
    newer view supersedes its older one (which fails with :class:`Cancelled`
    at once and is dropped before its next piece) unless another client waits
    for that same view; requests without a client id supersede nothing.  A job
    whose own computing passes ``budget_s``, or whose rate so far says it
    would take ``BUDGET_SLACK`` times that, fails with :class:`OverBudget`;
    more than ``MAX_JOBS`` maps in the making at once is :class:`Busy`.
    Finished maps are cached by view up to ``cache_bytes`` bytes in all (least
    recently used out first); nothing else keeps a finished map.  ``device``:
    where the maps and saves run (cpu, cuda, auto: resolved here, a
    :class:`~dicetrace.devices.DeviceError` for cuda without a GPU);
    ``self.device`` is its label (``"cpu"`` or ``"cuda: <GPU name>"``).
    """

    def __init__(self, threads: int | None = None, *, budget_s: float | None = None, cache_bytes: int | None = None,
                 device: str = "cpu"):
        self._device = resolve_device(device)  # a Device, resolved once (the server passes one)
        self.device = self._device.label
        self.threads = threads
        self.budget_s = MAP_BUDGET_S if budget_s is None else float(budget_s)
        if not self.budget_s > 0:
            raise ValueError(f"budget_s must be > 0 s, got {budget_s!r}")
        self.cache_bytes_max = CACHE_BYTES if cache_bytes is None else int(cache_bytes)
        self._lock = threading.Lock()
        self._wake = threading.Condition(self._lock)
        self._queue: deque[_Job] = deque()  # jobs waiting for their next turn
        self._jobs: dict[tuple, _Job] = {}  # view key -> its job (queued or running)
        self._latest: dict = {}  # client -> the key of the job it waits for (only while that job is unfinished)
        self._cache: OrderedDict[tuple, OutcomeMap] = OrderedDict()
        self._cache_nbytes = 0
        self._stopped = False
        self._throws = _DaemonPool(2, "dicetrace-explore-throw", max_waiting=MAX_THROWS_WAITING,
                                   what="throws to simulate")
        self._saves = _DaemonPool(1, "dicetrace-explore-save", max_waiting=MAX_SAVES_WAITING, what="saves")
        self.cancelled_count = 0
        self.computed_count = 0
        self.refused_count = 0
        self._running: dict = {}  # a token per piece being computed -> when it started (time.monotonic)
        self._serial = threading.Lock()  # parallel kernels one at a time, where the threading layer needs it
        for k in range(MAX_LANES):
            threading.Thread(target=self._loop, name=f"dicetrace-explore-map-{k}", daemon=True).start()

    # -- the cache ---------------------------------------------------------------------------------------------

    @property
    def cache_nbytes(self) -> int:
        """Bytes of the maps in the cache."""
        with self._lock:
            return self._cache_nbytes

    def cached(self, view: View) -> OutcomeMap | None:
        with self._lock:
            m = self._cache.get(view.key())
            if m is not None:
                self._cache.move_to_end(view.key())
            return m

    def _cache_put(self, key, m: OutcomeMap) -> None:  # under the lock
        n = map_nbytes(m)
        if n > self.cache_bytes_max:
            return
        old = self._cache.pop(key, None)
        if old is not None:
            self._cache_nbytes -= map_nbytes(old)
        self._cache[key] = m
        self._cache_nbytes += n
        while self._cache_nbytes > self.cache_bytes_max:
            _, out = self._cache.popitem(last=False)
            self._cache_nbytes -= map_nbytes(out)

    # -- maps --------------------------------------------------------------------------------------------------

    def submit_map(self, view: View, client: str = "") -> Future:
        """A future of ``view``'s map; this client's earlier request for another view is superseded.

        Raises :class:`Busy` when ``MAX_JOBS`` maps are in the making.
        """
        key = view.key()
        who = client if client else object()  # no client id: a client of its own
        with self._lock:
            if self._stopped:
                raise Cancelled("the explorer is stopping")
            prev = self._latest.pop(who, None) if client else None
            if prev is not None and prev != key:
                self._leave(who, prev)
            hit = self._cache.get(key)
            if hit is not None:
                self._cache.move_to_end(key)
                f: Future = Future()
                f.set_result(hit)
                return f
            job = self._jobs.get(key)
            if job is None:
                if len(self._jobs) >= MAX_JOBS:
                    raise Busy(f"the explorer is computing {len(self._jobs)} maps already (at most {MAX_JOBS}): "
                               "try again in a moment")
                job = _Job(view)
                self._jobs[key] = job
                self._queue.append(job)
                self._wake.notify_all()
            job.clients.add(who)
            if client:
                self._latest[who] = key
            return job.future

    def _leave(self, who, key) -> None:  # under the lock: ``who`` no longer waits for ``key``'s map
        job = self._jobs.get(key)
        if job is None:
            return
        job.clients.discard(who)
        if not job.clients:
            self._drop(job, Cancelled())
            self.cancelled_count += 1

    def _drop(self, job: _Job, exc: BaseException | None, result: OutcomeMap | None = None) -> None:
        """Under the lock: the job is over (its result, or ``exc``); nothing keeps it any longer."""
        job.cancelled = True
        if self._jobs.get(job.key) is job:
            del self._jobs[job.key]
        for who in job.clients:
            if self._latest.get(who) == job.key:
                del self._latest[who]
        job.clients.clear()
        with contextlib.suppress(Exception):  # InvalidStateError: already settled
            if exc is None:
                job.future.set_result(result)
            else:
                job.future.set_exception(exc)

    def progress(self, view: View) -> OutcomeMap | None:
        """``view``'s map as far as it is computed (complete once cached), or None before its first strip."""
        with self._lock:
            job = self._jobs.get(view.key())
            if job is not None and job.build is not None and job.build.map.rows_done > 0:
                return job.build.map
            return self._cache.get(view.key())

    def _may_start(self, now: float) -> bool:
        """Under the lock: may another lane start a piece now? (Only while every piece running is stuck.)"""
        if not self._running:
            return True
        if len(self._running) >= MAX_LANES or not _concurrent_kernels_ok():
            return False
        return all(now - t0 > STUCK_S for t0 in self._running.values())

    def _loop(self) -> None:
        while True:
            with self._lock:
                while True:
                    if self._stopped:
                        return
                    if self._queue and self._may_start(time.monotonic()):
                        job = self._queue.popleft()
                        if not job.cancelled:
                            break
                        del job
                        continue
                    # something queued behind a running piece: look again when that piece may count as stuck
                    self._wake.wait(timeout=0.1 if self._queue else None)
                known = [] if job.build is not None else [  # a coarser pass's points may be this grid's
                    m for m in self._cache.values() if replace(m.view, res=job.view.res) == job.view]
                me = object()
                self._running[me] = time.monotonic()
            self._run(job, known, me)
            # nothing of this job stays bound in this frame while the lane waits for the next one (its map may
            # have left the cache meanwhile: a lane keeps no map alive)
            del job, known, me

    def _run(self, job: _Job, known, me) -> None:
        """One piece of ``job`` on this lane (registered as running under ``me``), and what follows from it:
        cached and settled, refused, or queued for its next turn."""
        try:
            finished = self._turn(job, known)
        except BaseException as e:  # a bad configuration, over budget, ...
            with self._lock:
                del self._running[me]
                if not job.cancelled:
                    self.refused_count += isinstance(e, OverBudget)
                    self._drop(job, e)
                self._wake.notify_all()
            return
        with self._lock:
            del self._running[me]
            if finished and job.cancelled and not self._stopped:  # superseded as its last piece ran: keep it
                self._cache_put(job.key, job.build.map)
            if not job.cancelled:
                if finished:
                    self.computed_count += 1
                    self._cache_put(job.key, job.build.map)
                    self._drop(job, None, job.build.map)
                else:
                    self._queue.append(job)
            self._wake.notify_all()

    def _turn(self, job: _Job, known) -> bool:
        """One piece of ``job`` (on the worker's thread); True once its map is whole."""
        if job.build is None:
            job.build = MapBuild(job.view, known, self.threads, device=self._device)
            if job.build.done:
                return True
        b = job.build
        lanes = self.threads or _numba_threads()
        if job.chunk == 0:  # one IC per thread first: its time sizes the next pieces
            job.chunk = lanes
        t0 = time.perf_counter()
        with self._kernel_gate():
            n = b.step(job.chunk)
        dt = time.perf_counter() - t0
        if n > 0 and dt > 0:  # about CHUNK_S a piece, never less than an IC per thread, growing 8× at most
            job.chunk = int(min(max(lanes, CHUNK_S * n / dt), 8 * n))
        if b.done:
            return True
        if job.counted is None:  # the first piece may have compiled or loaded the kernel: not counted
            job.counted = 0
            return False
        job.spent_s += dt
        job.counted += n
        left = b.todo - b.thrown
        projected = job.spent_s + job.spent_s / max(job.counted, 1) * left
        if job.spent_s > self.budget_s or projected > BUDGET_SLACK * self.budget_s:
            nx, ny = job.view.res
            raise OverBudget(
                f"this {nx}×{ny} map would take about {projected:,.0f} s of computing ({job.counted:,} of its "
                f"{b.todo:,} throws took {job.spent_s:.1f} s), more than the explorer's {self.budget_s:g} s per map: "
                "ask for fewer pixels (res) or a longer time step (dt)")
        return False

    # -- throws, saves, the end --------------------------------------------------------------------------------

    def submit_throw(self, fn, *args) -> Future:
        return self._throws.submit(fn, *args)

    def submit_scan(self, view: View, folder: Path, name: str) -> Future:
        """A future of the save of ``view`` as a scan into ``folder/name``; :class:`Busy` when
        :data:`MAX_SAVES_WAITING` saves wait already."""
        return self._saves.submit(self._save, view, folder, name)

    def check_save_room(self) -> None:
        """:class:`Busy` when :data:`MAX_SAVES_WAITING` saves wait already (checked before a save's map is made)."""
        self._saves.check_room()

    def _save(self, view: View, folder: Path, name: str) -> dict:
        with self._kernel_gate():
            return save_scan(view, folder, name, self.threads, device=self._device)

    def _kernel_gate(self):
        """Held around every parallel kernel call (map pieces, saves) unless numba's threading layer takes
        calls from several threads at once: then nothing (see :func:`_concurrent_kernels_ok`); on a GPU always
        (one kernel call on the device at a time)."""
        if self._device.gpu:
            return self._serial
        return contextlib.nullcontext() if _concurrent_kernels_ok() else self._serial

    def cancel_all(self) -> None:
        """Every map in the making, and every throw and save waiting or running, fails with :class:`Cancelled` now, so
        the requests waiting for them answer at once (a map's piece, a throw or a save being computed ends on its own
        thread: a save leaves a resumable scan folder)."""
        with self._lock:
            for job in list(self._jobs.values()):
                self._drop(job, Cancelled("the explorer is stopping"))
            self._queue.clear()
        self._throws.cancel_all()
        self._saves.cancel_all()

    def shutdown(self) -> None:
        """Cancel every map, stop the threads; waits for nothing (a piece being computed ends on its own thread)."""
        with self._lock:
            self._stopped = True
            self._wake.notify_all()
        self.cancel_all()
        self._throws.shutdown(2)
        self._saves.shutdown(1)


_CONCURRENT_OK: bool | None = None


def _concurrent_kernels_ok() -> bool:
    """Whether numba's threading layer takes parallel kernels from several threads at once (tbb, omp: yes;
    workqueue: no, it aborts the process); False until the first parallel kernel has chosen the layer."""
    global _CONCURRENT_OK
    if _CONCURRENT_OK is None:
        import numba  # lazy: imports numba; `import dicetrace.explore` does not

        try:
            _CONCURRENT_OK = numba.threading_layer() in ("tbb", "omp")
        except ValueError:  # no parallel kernel has run yet
            return False
    return _CONCURRENT_OK


def _numba_threads() -> int:
    import numba  # lazy: imports numba; `import dicetrace.explore` does not

    return int(numba.get_num_threads())


def scan_folder_for(out: Path, name: str) -> Path:
    """The folder ``out/name`` for a saved scan, refusing a name that could leave ``out``."""
    if not isinstance(name, str) or not SCAN_NAME.match(name) or name in (".", ".."):
        raise ViewError("name", "a scan name is 1-64 letters, digits, '.', '_' or '-', starting with a letter or digit")
    folder = (Path(out) / name).resolve()
    if folder.parent != Path(out).resolve():
        raise ViewError("name", f"{name!r} would leave the output folder")
    return folder


def save_scan(view: View, out: Path, name: str, threads: int | None = None, *, device: str = "cpu") -> dict:
    """Write ``view`` as the dataset ``dicetrace scan`` would write, into ``out/name``, on ``device``; returns a summary."""
    from dicetrace.scan import read_manifest, scan  # lazy: imports numba; `import dicetrace.explore` does not

    folder = scan_folder_for(out, name)
    report = scan(view.grid(), folder, config=view.config(), threads=threads, device=device)
    return {"path": str(folder), "n_ics": report.n_ics, "chunks": report.n_chunks, "wall_s": report.wall_s,
            "device": read_manifest(folder)["definition"]["device"]}
