"""Run a scan: chunks of ICs through the batch kernel, streamed into a scan folder.

``scan`` runs or resumes a scan (in memory, locally or on Dask) and
``iter_scan`` streams its chunk tables; what the folder holds and how it
survives a kill, damage and a second writer is described in
:mod:`dicetrace.scan.folder`.
"""
from __future__ import annotations

import contextlib
import itertools
import math
import os
import time
from collections import deque
from collections.abc import Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path

import pyarrow as pa
from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TaskProgressColumn,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

from dicetrace.compile_clock import CompileClock, running_rate
from dicetrace.devices import Device, check_device, device_label, resolve_device
from dicetrace.ics import Grid, Points, Sample
from dicetrace.memory import available_memory
from dicetrace.params import Config, resolve_config
from dicetrace.saving import NOT_GIVEN, Record, record_with_events, summary_record, wants_events
from dicetrace.scan.definition import DEFAULT_CHUNK, ScanDefinition, device_kind
from dicetrace.scan.poses import HandThrows, ThrowTable
from dicetrace.sinks._common import human_bytes, output_folder
from dicetrace.scan.estimate import TABLE_MEMORY_PER_IC, TABLE_MEMORY_PER_IC_EVENTS
from dicetrace.scan.dask import _check_dask, _iter_dask, _open_dask, worker_device
from dicetrace.scan.folder import (
    _check_int,
    _check_space_finite,
    check_folder,
    _FolderLock,
    _version,
    _with_metadata,
    compute_chunk,
    flush_chunk_log,
    prepare_folder,
    write_chunk,
)


# -- progress ------------------------------------------------------------------------------------


class _Progress:
    """A rich progress bar: ICs done, rate, ETA (a no-op when disabled).

    It never decides the run: a terminal that goes away (a write that fails)
    ends the bar, not the scan.
    """

    def __init__(self, enabled: bool, total: int, done: int, label: str, clock: CompileClock | None = None):
        self.enabled = enabled
        self.clock = clock
        self.t0 = time.perf_counter()
        self.base = done
        if not enabled:
            return
        self.bar = Progress(
            TextColumn("[bold]{task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TextColumn("ICs"),
            TaskProgressColumn(),
            TextColumn("{task.fields[rate]}"),
            TimeElapsedColumn(),
            TextColumn("ETA"),
            TimeRemainingColumn(),
            console=Console(stderr=True),
            transient=True,
        )
        self.task = self.bar.add_task(label, total=total, completed=done, rate="")
        self._guard(self.bar.start)

    def _guard(self, fn, *args, **kwargs) -> None:
        try:
            fn(*args, **kwargs)
        except (OSError, ValueError):  # the terminal went away: no more bar
            self.enabled = False
            with contextlib.suppress(OSError, ValueError):
                self.bar.stop()

    def advance(self, n: int, done_total: int) -> None:
        if not self.enabled:
            return
        dt = time.perf_counter() - self.t0
        new = done_total - self.base
        compiling = self.clock.seconds if self.clock is not None else 0.0  # a rate of the throws, not the compiler
        rate = f"{running_rate(new, dt, compiling):,.0f} ICs/s" if dt > compiling and new > 0 else ""
        self._guard(self.bar.update, self.task, advance=n, rate=rate)

    def close(self) -> None:
        if self.enabled:
            self.enabled = False
            with contextlib.suppress(OSError, ValueError):
                self.bar.stop()


# -- running ---------------------------------------------------------------------------------------


@dataclass
class ScanReport:
    """What a run of :func:`scan` into a folder did."""

    path: Path
    n_ics: int
    n_chunks: int
    chunks_skipped: int
    chunks_computed: int
    wall_s: float

    @property
    def complete(self) -> bool:
        return self.chunks_skipped + self.chunks_computed == self.n_chunks

    @property
    def rate_ics_s(self) -> float:
        """ICs computed per second of the time not spent compiling the kernels."""
        return running_rate(self.ics_computed, self.wall_s, self.compile_s)

    ics_computed: int = 0
    #: Of ``wall_s``, the seconds numba spent compiling in this process (a first run on a cold kernel cache).
    compile_s: float = 0.0


_SPACES = (Grid, Sample, Points, HandThrows, ThrowTable)


def _device_name(device):
    """A :class:`~dicetrace.devices.Device` as the name of its kind (the scan records the label it resolves to, on
    Dask the workers', and each process resolves it once: ``folder.compute_chunk``); a name as it is."""
    return device.kind if isinstance(device, Device) else device


def _definition(space, config, chunk, options, device=None, record=None, events=NOT_GIVEN,
                where: str = "scan") -> ScanDefinition:
    """The scan's definition: ``space`` itself where it is one, else made of the arguments.  ``record``: None or
    the exact contact events (``Record.events_only()``; trace channels are refused); ``events``: the deprecated
    keyword (None, its old default, is not giving it)."""
    if device is not None:
        check_device(device)
    given = events is not NOT_GIVEN and events is not None
    record = summary_record(record_with_events(record, events if given else NOT_GIVEN, where, stacklevel=4), where)
    if isinstance(space, ScanDefinition):
        if (config is not None or device is not None or record is not None or given
                or any(v is not None for v in options.values())):
            raise ValueError("give a ScanDefinition (its device and events included) or a space with its "
                             "configuration, not both")
        return space
    if not isinstance(space, _SPACES):
        raise TypeError(
            f"space must be a Grid, Sample or Points (dicetrace.ics), HandThrows or ThrowTable (dicetrace.scan.poses) "
            f"or a ScanDefinition, not {type(space).__name__}"
        )
    return ScanDefinition(space, resolve_config(config, **options), chunk, events=wants_events(record))


def _on_device(defn: ScanDefinition, device: str | None, client=None) -> ScanDefinition:
    """``defn`` on the device ``device`` (cpu, cuda, auto; None: the definition's own) as it resolves here, or on
    a worker of the Dask ``client`` (a :class:`~dicetrace.devices.DeviceError` where there is no GPU for cuda)."""
    want = device_kind(defn.device) if device is None else device
    label = worker_device(client, want) if client is not None else device_label(resolve_device(want))
    return defn if label == defn.device else replace(defn, device=label)


def _chunks(defn: ScanDefinition, todo: Iterable[int], client, threads) -> Iterator[tuple[int, pa.Table]]:
    """(chunk index, rolls table) of the chunks ``todo``: computed here in order, or on Dask as they complete."""
    if client is not None:
        return _iter_dask(defn, todo, client, threads)
    return ((c, compute_chunk(defn, c, threads=threads)) for c in todo)


def iter_scan(
    space,
    *,
    config: Config | str | None = None,
    chunk: int = DEFAULT_CHUNK,
    chunks: Iterable[int] | None = None,
    threads: int | None = None,
    dask=None,
    n_workers: int | None = None,
    device: str | None = None,
    record: Record | None = None,
    events=NOT_GIVEN,
    **options,
) -> Iterator[tuple[int, pa.Table]]:
    """Stream a scan: yields ``(chunk_index, rolls_table)`` as chunks finish.

    Local chunks come in order; Dask chunks (``dask=True`` for a local
    cluster, an address, or a ``Client``) as they complete.  ``chunks``
    restricts the run to those chunk indices.  Arguments as :func:`scan`.
    """
    device = _device_name(device)
    defn = _definition(space, config, chunk, options, device, record, events, "iter_scan")
    _check_int(threads, "threads", 1)
    _check_int(n_workers, "n_workers", 1)
    _check_dask(dask)
    todo = range(defn.n_chunks) if chunks is None else chunks
    client, closers = _open_dask(dask, n_workers, device=device or defn.device) if dask else (None, [])
    try:
        defn = _on_device(defn, device, client)
        yield from _chunks(defn, todo, client, threads)
    finally:
        for x in closers:
            x.close()


def _check_scan_args(out, threads, n_workers, max_chunks, wait, progress, dask) -> None:
    if out is not None and not isinstance(out, (str, os.PathLike)):
        raise TypeError(f"out must be a folder path (str or os.PathLike) or None, not {type(out).__name__}")
    _check_int(threads, "threads", 1)
    _check_int(n_workers, "n_workers", 1)
    _check_int(max_chunks, "max_chunks", 0)
    if isinstance(wait, bool) or not isinstance(wait, (int, float)) or not math.isfinite(wait) or wait < 0:
        raise ValueError(f"wait must be a finite number of seconds >= 0, got {wait!r}")
    if not isinstance(progress, bool):
        raise TypeError(f"progress must be True or False, not {type(progress).__name__}")
    _check_dask(dask)


def _check_table_memory(defn: ScanDefinition) -> None:
    """Refuse (ValueError) a scan whose whole rolls table, held in memory, would not fit: a folder streams it."""
    need = defn.size * (TABLE_MEMORY_PER_IC_EVENTS if defn.events else TABLE_MEMORY_PER_IC)
    avail = available_memory()
    if avail is not None and need > avail:
        raise ValueError(f"out: the rolls table of {defn.size:,} ICs held in memory needs about {human_bytes(need)}, "
                         f"{human_bytes(avail)} available: give out= (a folder) to stream it to disk chunk by chunk")


def scan(
    space,
    out=None,
    *,
    config: Config | str | None = None,
    chunk: int = DEFAULT_CHUNK,
    threads: int | None = None,
    progress: bool = False,
    dask=None,
    n_workers: int | None = None,
    max_chunks: int | None = None,
    wait: float = 0.0,
    device: str | None = None,
    record: Record | None = None,
    events=NOT_GIVEN,
    **options,
):
    """Throw the die from every IC of an IC space (summaries only).

    Parameters
    ----------
    space
        A :class:`~dicetrace.ics.Grid`, :class:`~dicetrace.ics.Sample` or
        :class:`~dicetrace.ics.Points` (ICs in the slice's L convention; they
        are converted to the preset's), a space of throws from their own poses
        (:class:`~dicetrace.scan.poses.HandThrows`: drawn from a hand-throw
        model; :class:`~dicetrace.scan.poses.ThrowTable`: a throw table's
        rows; on the CPU; their rows add ``qx, qy, qz, qw, z0_cm``), or a full
        :class:`ScanDefinition`.  The die is the configuration's (any box,
        loaded or not: ``half_extents_cm=``, ``load_fraction=``, ``load_cm=``).
    out
        A folder: the scan is written there as a Parquet dataset, chunk by
        chunk, resuming whatever a previous run of the same scan finished
        (after verifying those chunks' checksums).
        None: nothing is written and the whole rolls table is returned.
    config, **options
        The configuration: a Config, or the keyword options of
        :func:`dicetrace.params.make_config` (see :func:`dicetrace.params.resolve_config`).
    chunk
        ICs per chunk (file, Dask task).  Part of the definition.
    threads
        numba threads (None: all; Dask tasks default to 1 each).
    progress
        Show a progress bar (ICs done, rate, ETA) on stderr.
    dask
        None: run here.  True: on a new local Dask cluster (``n_workers``
        processes of one thread); a scheduler address or a
        ``dask.distributed.Client``: on that cluster.  Results are identical.
        An address is connected to (within ``DASK_CONNECT_TIMEOUT_S``)
        before anything is written.
    max_chunks
        Compute at most this many chunks in this run (>= 0; a size knob; the
        folder stays resumable).
    wait
        Seconds to wait for another scan writing into ``out`` (it holds the
        folder's lock) before refusing with :class:`ScanBusyError`.
    device
        Where the throws run: ``"cpu"``, ``"cuda"`` or ``"auto"``, as in
        :func:`~dicetrace.simulate.simulate_batch` (None: ``"cpu"``, or a
        ScanDefinition's own device).  It resolves here, or on Dask on a
        worker (and again by every chunk task on its worker), before anything
        is written; the definition records the device it resolved to (its
        label, ``"cpu"`` or ``"cuda: <GPU name>"``), as does each chunk's
        metadata.  A folder holding the same scan run on another device is
        refused (:class:`~dicetrace.scan.folder.DeviceMismatchError`): a
        GPU's throws may differ from the CPU's by rounding.
    record
        What the rows keep besides the summaries: ``Record.events_only()``,
        the exact contact events (the contact integrators, on either device),
        as ``simulate_batch(..., record=Record.events_only())``: each row's
        contact sets are then those inside the sub-steps and a column
        ``contact_times_s`` says when each began.  Part of the definition
        (None: no events, or a ScanDefinition's own).  A scan keeps no
        per-step trace: a record asking for trace channels is refused.
    events
        Deprecated: ``events=True`` is ``record=Record.events_only()``; it
        warns, and goes in the next release.

    Returns
    -------
    pyarrow.Table (``out`` is None: sorted by ``ic_id``; refused with a
    ValueError, before any work, when it would not fit in the memory
    available) or :class:`ScanReport`.

    Raises
    ------
    TypeError, ValueError
        A bad argument (named), before anything is computed or written.
    ScanMismatchError, FileExistsError
        ``out`` holds another scan, or files that are not a scan, or
        (:class:`~dicetrace.scan.folder.ForeignFileError`, named) something in
        ``rolls/`` that is none of the scan's chunk files.
    ScanBusyError
        Another scan is writing into ``out``.
    SchedulerError
        The Dask scheduler cannot be reached or is not one.
    dicetrace.devices.DeviceError
        ``device="cuda"`` where there is no GPU (before anything is written).
    dicetrace.sinks._common.OutputError
        ``out`` cannot be created or written (the message names it); on a
        full disk the chunks finished so far are kept.
    """
    device = _device_name(device)
    defn = _definition(space, config, chunk, options, device, record, events)
    _check_scan_args(out, threads, n_workers, max_chunks, wait, progress, dask)
    _check_space_finite(defn)
    t0 = time.perf_counter()
    if out is None:
        _check_table_memory(defn)
    folder = None if out is None else output_folder(out, what="scan folder")
    if not dask:
        defn = _on_device(defn, device)
        if folder is not None:
            check_folder(folder, defn)  # refuse at once, without waiting for a lock (read only)
    client, closers = _open_dask(dask, n_workers, device=device or defn.device) if dask else (None, [])
    clock = CompileClock().start()  # what of the wall time was compiling, told apart in the report's rate
    try:
        if client is not None:
            defn = _on_device(defn, device, client)
            if folder is not None:
                check_folder(folder, defn)
        if folder is None:
            table = pa.concat_tables([t for _, t in _chunks(defn, range(defn.n_chunks), client, threads)])
            if dask:
                table = table.sort_by("ic_id")
            return _with_metadata(table, {"dicetrace_version": _version(), "scan": defn.to_dict(),
                                          "config": defn.config.as_dict(), "device": defn.device, "die": defn.die,
                                          "l_convention": defn.config.preset.l_convention})
        with _FolderLock(folder, float(wait)):  # made and locked at once: nothing touches it before
            return _run_into(folder, defn, t0, threads=threads, progress=progress, client=client,
                             max_chunks=max_chunks, clock=clock)
    finally:
        clock.stop()
        for x in closers:
            x.close()


def _run_into(folder: Path, defn: ScanDefinition, t0: float, *, threads, progress, client, max_chunks,
              clock: CompileClock):
    done = prepare_folder(folder, defn)
    todo: Iterable[int] = (c for c in range(defn.n_chunks) if c not in done)
    if max_chunks is not None:
        todo = itertools.islice(todo, max_chunks)
    ics_done = sum(stop - start for start, stop in map(defn.chunk_range, done))
    bar = _Progress(progress, defn.size, int(ics_done), f"scan {folder.name}", clock)
    computed = 0
    ics_now = 0
    pending: deque = deque()

    def settle(block: bool) -> None:
        nonlocal computed, ics_now, ics_done
        while pending and (block or pending[0][0].done()):
            fut, rows = pending.popleft()
            fut.result()
            computed += 1
            ics_now += rows
            ics_done += rows
            bar.advance(rows, int(ics_done))

    chunks = _chunks(defn, todo, client, threads)
    try:
        # A writer thread encodes and writes chunk c while the kernel (which
        # releases the GIL) computes chunk c+1.  On an interrupt the chunks
        # already computed are still written (the pool's exit waits for them).
        with ThreadPoolExecutor(max_workers=1, thread_name_prefix="dicetrace-scan-writer") as writer:
            for c, table in chunks:
                pending.append((writer.submit(write_chunk, folder, defn, c, table), table.num_rows))
                settle(block=len(pending) > 1)
            settle(block=True)
    except BaseException:
        with contextlib.suppress(OSError):  # the chunk log of the chunks written, if the disk lets us
            flush_chunk_log(folder)
        raise
    else:
        flush_chunk_log(folder)
    finally:
        close = getattr(chunks, "close", None)
        if close is not None:
            close()
        bar.close()
    return ScanReport(
        path=folder,
        n_ics=defn.size,
        n_chunks=defn.n_chunks,
        chunks_skipped=len(done),
        chunks_computed=computed,
        wall_s=time.perf_counter() - t0,
        ics_computed=ics_now,
        compile_s=clock.seconds,
    )


