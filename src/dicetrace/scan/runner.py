"""Run a scan: chunks of ICs through the batch kernel, streamed to Parquet.

A scan folder holds ``_scan.json`` (the manifest: the scan definition, the
dicetrace version) and one Parquet file per finished chunk,
``part-NNNNNN.parquet``, each written under a hidden temporary name and
renamed when complete.  So a Ctrl-C or a kill loses at most the chunks in
flight; running the same scan again skips the finished chunks and ends with
exactly one row per IC.  A different definition against an existing folder
is refused (:class:`ScanMismatchError`), never mixed in.

The folder is a plain Parquet dataset: ``pandas.read_parquet(folder)`` reads
it (files whose names start with ``_`` or ``.`` are not data).
"""

from __future__ import annotations

import json
import os
import time
import uuid
from collections import deque
from collections.abc import Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from dicetrace.params import Config, resolve_config
from dicetrace.scan.definition import DEFAULT_CHUNK, ScanDefinition, describe_differences
from dicetrace.simulate import DEFAULT_CAP, simulate_batch
from dicetrace.tables import rolls_table

MANIFEST = "_scan.json"
METADATA_KEY = b"dicetrace"
DICTIONARY_COLUMNS = ["preset", "integrator", "status", "outcome", "dt_s", "k"]


class ScanMismatchError(ValueError):
    """The folder holds a scan with a different definition."""


def part_name(c: int) -> str:
    return f"part-{c:06d}.parquet"


def _version() -> str:
    import dicetrace

    return dicetrace.__version__


# -- computing one chunk ----------------------------------------------------------------------


def compute_chunk(defn: ScanDefinition, c: int, *, threads: int | None = None, cap: int = DEFAULT_CAP) -> pa.Table:
    """The rolls table of chunk ``c`` of a scan (no metadata).

    ``threads``: numba threads for this chunk (None: numba's current setting).
    The rows do not depend on it, nor on the chunk size: every IC is the
    serial kernel's result for that IC.
    """
    start, stop = defn.chunk_range(c)
    blk = defn.space.block(start, stop)
    batch = simulate_batch(
        blk.ics, config=defn.config, l_convention=defn.space.slice.l_convention, threads=threads, cap=cap
    )
    return rolls_table(batch, coords=blk.coords, ic_ids=blk.ic_id, index=blk.index)


def _chunk_task(defn_dict: dict, c: int, threads: int | None) -> tuple[int, pa.Table]:
    """A Dask task: chunk ``c`` of the scan ``defn_dict`` (module level: sent by reference)."""
    return c, compute_chunk(ScanDefinition.from_dict(defn_dict), c, threads=threads)


def chunk_metadata(defn: ScanDefinition, c: int) -> dict:
    start, stop = defn.chunk_range(c)
    return {
        "dicetrace_version": _version(),
        "scan": defn.to_dict(),
        "config": defn.config.as_dict(),
        "l_convention": defn.config.preset.l_convention,
        "chunk_index": c,
        "ic_range": [start, stop],
    }


def _with_metadata(table: pa.Table, meta: dict) -> pa.Table:
    md = dict(table.schema.metadata or {})
    md[METADATA_KEY] = json.dumps(meta, sort_keys=True).encode()
    return table.replace_schema_metadata(md)


# -- the dataset folder ----------------------------------------------------------------------


def read_manifest(folder) -> dict:
    p = Path(folder) / MANIFEST
    if not p.is_file():
        raise FileNotFoundError(f"{str(folder)!r} is not a dicetrace scan folder (no {MANIFEST})")
    return json.loads(p.read_text())


def _atomic_write_text(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}-{uuid.uuid4().hex[:8]}.tmp")
    try:
        tmp.write_text(text)
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def prepare_folder(folder, defn: ScanDefinition) -> set[int]:
    """Create or check the scan folder; return the chunks already finished.

    Raises :class:`ScanMismatchError` when the folder holds another scan, and
    FileExistsError when it holds files that are not a dicetrace scan.
    Leftover temporary files of interrupted writes are removed; a chunk file
    with the wrong number of rows is treated as unfinished.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    mpath = folder / MANIFEST
    want = defn.to_dict()
    if mpath.exists():
        try:
            have = json.loads(mpath.read_text())["definition"]
        except (ValueError, KeyError) as e:
            raise ScanMismatchError(f"{str(folder)!r}: unreadable scan manifest {MANIFEST} ({e})") from None
        if json.dumps(have, sort_keys=True) != json.dumps(want, sort_keys=True):
            diffs = describe_differences(have, want)
            shown = "; ".join(diffs[:4]) + (f"; and {len(diffs) - 4} more" if len(diffs) > 4 else "")
            raise ScanMismatchError(
                f"{str(folder)!r} holds a different scan ({shown}). "
                "Use another --out folder, or delete this one to start over."
            )
    else:
        data = [p for p in folder.iterdir() if not p.name.startswith(".")]
        if data:
            raise FileExistsError(
                f"{str(folder)!r} is not empty and holds no dicetrace scan ({MANIFEST} missing): use another folder"
            )
        manifest = {
            "format": want["format"],
            "dicetrace_version": _version(),
            "definition": want,
            "n_ics": defn.size,
            "n_chunks": defn.n_chunks,
            "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        }
        _atomic_write_text(mpath, json.dumps(manifest, indent=1, sort_keys=True))
    for p in folder.glob(".part-*.tmp"):
        p.unlink(missing_ok=True)
    done = set()
    for c in range(defn.n_chunks):
        p = folder / part_name(c)
        if p.exists():
            start, stop = defn.chunk_range(c)
            try:
                ok = pq.read_metadata(p).num_rows == stop - start
            except Exception:
                ok = False
            if ok:
                done.add(c)
    return done


def write_chunk(folder, defn: ScanDefinition, c: int, table: pa.Table) -> Path:
    """Write chunk ``c`` atomically (temporary name, then rename)."""
    path = Path(folder) / part_name(c)
    tmp = path.with_name(f".{path.name}.{os.getpid()}-{uuid.uuid4().hex[:8]}.tmp")
    try:
        pq.write_table(
            _with_metadata(table, chunk_metadata(defn, c)),
            tmp,
            compression="zstd",
            use_dictionary=DICTIONARY_COLUMNS,  # high-cardinality columns gain nothing and cost time
        )
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
    return path


# -- progress ------------------------------------------------------------------------------------


class _Progress:
    """A rich progress bar: ICs done, rate, ETA (a no-op when disabled)."""

    def __init__(self, enabled: bool, total: int, done: int, label: str):
        self.enabled = enabled
        self.t0 = time.perf_counter()
        self.base = done
        if not enabled:
            return
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
        )
        self.bar.start()
        self.task = self.bar.add_task(label, total=total, completed=done, rate="")

    def advance(self, n: int, done_total: int) -> None:
        if not self.enabled:
            return
        dt = time.perf_counter() - self.t0
        new = done_total - self.base
        rate = f"{new / dt:,.0f} ICs/s" if dt > 0 and new > 0 else ""
        self.bar.update(self.task, advance=n, rate=rate)

    def close(self) -> None:
        if self.enabled:
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
        return 0.0 if self.wall_s <= 0 else self.ics_computed / self.wall_s

    ics_computed: int = 0


def _definition(space, config, chunk, options) -> ScanDefinition:
    if isinstance(space, ScanDefinition):
        if config is not None or any(v is not None for v in options.values()):
            raise ValueError("give a ScanDefinition or a space with its configuration, not both")
        return space
    return ScanDefinition(space, resolve_config(config, **options), chunk)


def _open_dask(dask, n_workers):
    """(client, closers) for ``dask``: True (a LocalCluster), an address, or a Client."""
    from dask.distributed import Client, LocalCluster

    if isinstance(dask, Client):
        return dask, []
    if isinstance(dask, str):
        # distributed's handshake can trip (an AssertionError in Client) when the
        # scheduler is still winding down another client's futures: try again once.
        try:
            client = Client(dask)
        except (AssertionError, OSError):
            time.sleep(1.0)
            client = Client(dask)
        return client, [client]
    cluster = LocalCluster(
        n_workers=n_workers or os.cpu_count() or 1, threads_per_worker=1, processes=True, dashboard_address=":0"
    )
    client = Client(cluster)
    return client, [client, cluster]


def _iter_dask(defn: ScanDefinition, todo: list[int], dask, n_workers, threads) -> Iterator[tuple[int, pa.Table]]:
    from dask.distributed import as_completed

    client, closers = _open_dask(dask, n_workers)
    futures = []
    try:
        d = defn.to_dict()
        futures = [
            client.submit(_chunk_task, d, c, threads or 1, key=f"dicetrace-scan-{uuid.uuid4().hex[:8]}-{c}", pure=False)
            for c in todo
        ]
        for fut in as_completed(futures):
            c, table = fut.result()
            fut.release()
            yield c, table
    finally:
        for f in futures:
            f.cancel()
        for x in closers:
            x.close()


def iter_scan(
    space,
    *,
    config: Config | str | None = None,
    chunk: int = DEFAULT_CHUNK,
    chunks: Iterable[int] | None = None,
    threads: int | None = None,
    dask=None,
    n_workers: int | None = None,
    **options,
) -> Iterator[tuple[int, pa.Table]]:
    """Stream a scan: yields ``(chunk_index, rolls_table)`` as chunks finish.

    Local chunks come in order; Dask chunks (``dask=True`` for a local
    cluster, an address, or a ``Client``) as they complete.  ``chunks``
    restricts the run to those chunk indices.  Arguments as :func:`scan`.
    """
    defn = _definition(space, config, chunk, options)
    todo = list(range(defn.n_chunks)) if chunks is None else list(chunks)
    if dask:
        yield from _iter_dask(defn, todo, dask, n_workers, threads)
        return
    for c in todo:
        yield c, compute_chunk(defn, c, threads=threads)


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
    **options,
):
    """Throw the die from every IC of an IC space (summaries only).

    Parameters
    ----------
    space
        A :class:`~dicetrace.ics.Grid`, :class:`~dicetrace.ics.Sample` or
        :class:`~dicetrace.ics.Points` (ICs in the slice's L convention; they
        are converted to the preset's), or a full :class:`ScanDefinition`.
    out
        A folder: the scan is written there as a Parquet dataset, chunk by
        chunk, resuming whatever a previous run of the same scan finished.
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
    max_chunks
        Compute at most this many chunks in this run (a size knob; the
        folder stays resumable).

    Returns
    -------
    pyarrow.Table (``out`` is None: sorted by ``ic_id``) or :class:`ScanReport`.
    """
    defn = _definition(space, config, chunk, options)
    t0 = time.perf_counter()
    if out is None:
        tables = [t for _, t in iter_scan(defn, threads=threads, dask=dask, n_workers=n_workers)]
        table = pa.concat_tables(tables)
        if dask:
            table = table.sort_by("ic_id")
        return _with_metadata(table, {"dicetrace_version": _version(), "scan": defn.to_dict(),
                                      "config": defn.config.as_dict(), "l_convention": defn.config.preset.l_convention})
    folder = Path(out)
    done = prepare_folder(folder, defn)
    todo = [c for c in range(defn.n_chunks) if c not in done]
    if max_chunks is not None:
        todo = todo[: max(0, int(max_chunks))]
    ics_done = sum(stop - start for start, stop in map(defn.chunk_range, done))
    bar = _Progress(progress, defn.size, int(ics_done), f"scan {folder.name}")
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

    try:
        # A writer thread encodes and writes chunk c while the kernel (which
        # releases the GIL) computes chunk c+1.  On an interrupt the chunks
        # already computed are still written (the pool's exit waits for them).
        with ThreadPoolExecutor(max_workers=1, thread_name_prefix="dicetrace-scan-writer") as writer:
            for c, table in iter_scan(defn, chunks=todo, threads=threads, dask=dask, n_workers=n_workers):
                pending.append((writer.submit(write_chunk, folder, defn, c, table), table.num_rows))
                settle(block=len(pending) > 1)
            settle(block=True)
    finally:
        bar.close()
    return ScanReport(
        path=folder,
        n_ics=defn.size,
        n_chunks=defn.n_chunks,
        chunks_skipped=len(done),
        chunks_computed=computed,
        wall_s=time.perf_counter() - t0,
        ics_computed=ics_now,
    )
