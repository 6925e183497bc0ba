"""Run a scan: chunks of ICs through the batch kernel, streamed to Parquet.

A scan folder holds ``_scan.json`` (the manifest: the scan definition, the
dicetrace version), one Parquet file per finished chunk,
``part-NNNNNN.parquet``, and the manifest's chunk log ``_scan.chunks.jsonl``
(one line per finished chunk: its file, rows, size and SHA-256).  Each chunk
is written under a hidden temporary name, its checksum logged, and then
renamed.  So a Ctrl-C or a kill loses at most the chunks in flight; running
the same scan again verifies the finished chunks against their checksums
(recomputing, with a :class:`ScanWarning`, any that are damaged), skips the
good ones and ends with exactly one row per IC.  A different definition
against an existing folder is refused (:class:`ScanMismatchError`), never
mixed in.  One writer at a time: a scan holds the folder's lock
(``.dicetrace-scan.lock``, via ``filelock``) while it writes; a second one
waits at most ``wait`` seconds, then refuses (:class:`ScanBusyError`),
touching nothing.

The folder is a plain Parquet dataset: ``pandas.read_parquet(folder)`` reads
it (files whose names start with ``_`` or ``.`` are not data).
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import os
import re
import time
import uuid
import warnings
from collections import deque
from collections.abc import Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from dicetrace.ics import Grid, Points, Sample
from dicetrace.params import Config, resolve_config
from dicetrace.scan.definition import DEFAULT_CHUNK, ScanDefinition, describe_differences
from dicetrace.simulate import DEFAULT_CAP, simulate_batch
from dicetrace.sinks._common import (
    OutputError,
    free_bytes,
    human_bytes,
    make_folders,
    output_folder,
    remove_folders,
    remove_quietly,
)
from dicetrace.tables import rolls_table

MANIFEST = "_scan.json"
#: The manifest's chunk log: one JSON line per finished chunk (file, rows, bytes, sha256).
CHUNK_LOG = "_scan.chunks.jsonl"
#: The folder's writer lock (held by the one scan writing into it).
LOCK = ".dicetrace-scan.lock"
METADATA_KEY = b"dicetrace"
DICTIONARY_COLUMNS = ["preset", "integrator", "status", "outcome", "dt_s", "k"]
#: Longest wait for a Dask scheduler to answer, s (the message of a failed connection states it).
DASK_CONNECT_TIMEOUT_S = 10.0
#: Bytes on disk per IC, a round upper estimate (measured 80–110 on the writeup's windows).
BYTES_PER_IC = 128
#: Bytes on disk per chunk file beyond its rows (Parquet footer, the definition in its metadata; measured ~11 KiB).
BYTES_PER_CHUNK = 16 * 1024
#: Memory per IC of a chunk in flight, bytes (contact-set buffers, summaries, the Arrow table).
MEMORY_PER_IC = 1024
_PART = re.compile(r"^part-(\d{6,})\.parquet$")


class ScanMismatchError(ValueError):
    """The folder holds a scan with a different definition."""


class ScanBusyError(RuntimeError):
    """Another scan holds the folder's writer lock."""


class CorruptChunkError(ValueError):
    """A chunk file does not match the checksum recorded when it was written (the message names the file)."""


class SchedulerError(ConnectionError):
    """The Dask scheduler could not be reached, or is not one."""


class ScanWarning(UserWarning):
    """Something a scan repaired on the way (a damaged chunk recomputed)."""


def part_name(c: int) -> str:
    return f"part-{c:06d}.parquet"


def _version() -> str:
    import dicetrace

    return dicetrace.__version__


# -- checking arguments -------------------------------------------------------------------------


def _check_int(value, name: str, lo: int, *, none: bool = True) -> int | None:
    if value is None and none:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < lo:
        more = " or None" if none else ""
        raise ValueError(f"{name} must be an integer >= {lo}{more}, got {value!r}")
    return int(value)


def _check_space_finite(defn: ScanDefinition) -> None:
    """Refuse a space whose ICs overflow: the corners of a window or box (an IC is affine in its coordinates), or every point."""
    space = defn.space
    if isinstance(space, (Grid, Sample)):
        box = space.window if isinstance(space, Grid) else space.box
        coords = np.array(list(itertools.product(*box)), dtype=np.float64)
    else:
        coords = np.array(space.coords, dtype=np.float64)
    with np.errstate(over="ignore", invalid="ignore"):
        ics = np.asarray(space.slice.ics(coords), dtype=np.float64).reshape(-1, 6)
    bad = ~np.isfinite(ics).all(axis=1)
    if bad.any():
        at = ", ".join(f"{float(v):g}" for v in coords[int(np.argmax(bad))])
        where = "window" if isinstance(space, Grid) else "box" if isinstance(space, Sample) else "points"
        raise ValueError(f"the scan's {where} gives non-finite ICs (at {at} on slice {space.slice.name!r}): "
                         "its coordinates are too large")


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
    try:
        return json.loads(p.read_text())
    except (OSError, ValueError) as e:
        raise ValueError(f"{str(p)!r}: unreadable scan manifest ({' '.join(str(e).split())})") from None


def _atomic_write_text(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}-{uuid.uuid4().hex[:8]}.tmp")
    try:
        with open(tmp, "w") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def file_sha256(path) -> tuple[str, int]:
    """(SHA-256 hex digest, size in bytes) of a file."""
    with open(path, "rb") as f:
        digest = hashlib.file_digest(f, "sha256")
        size = f.tell()
    return digest.hexdigest(), size


def read_chunk_log(folder) -> dict[int, dict]:
    """The chunk log of a scan folder: chunk index → its last entry (file, rows, bytes, sha256).

    A torn last line (a write killed half way) is skipped: that chunk's
    file was never renamed into place.
    """
    entries: dict[int, dict] = {}
    try:
        with open(Path(folder) / CHUNK_LOG) as f:
            for line in f:
                try:
                    e = json.loads(line)
                    entries[int(e["chunk"])] = e
                except (ValueError, KeyError, TypeError):
                    continue
    except FileNotFoundError:
        pass
    return entries


def _append_chunk_log(folder: Path, entry: dict) -> None:
    with open(folder / CHUNK_LOG, "a") as f:
        f.write(json.dumps(entry, sort_keys=True) + "\n")
        f.flush()
        os.fsync(f.fileno())


def chunk_files(folder) -> dict[int, Path]:
    """Chunk index → path of every ``part-NNNNNN.parquet`` in ``folder`` (one listing, any number of chunks)."""
    folder = Path(folder)
    out = {}
    with os.scandir(folder) as it:
        for e in it:
            m = _PART.match(e.name)
            if m:
                out[int(m.group(1))] = folder / e.name
    return dict(sorted(out.items()))


#: Files this process has hashed (or written), by path: (size, mtime_ns, sha256).  A file whose size and
#: modification time have not changed since is not hashed again (a scan's summary, map and recording
#: each read the folder); another process always hashes afresh.
_HASHED: dict[str, tuple[int, int, str]] = {}


def _remember(path: Path, digest: str) -> None:
    try:
        st = os.stat(path)
    except OSError:
        return
    _HASHED[str(Path(path).absolute())] = (st.st_size, st.st_mtime_ns, digest)


def _known_digest(path: Path) -> str | None:
    try:
        st = os.stat(path)
    except OSError:
        return None
    hit = _HASHED.get(str(Path(path).absolute()))
    return hit[2] if hit is not None and hit[:2] == (st.st_size, st.st_mtime_ns) else None


def verify_chunk(path: Path, entry: dict | None, rows: int) -> str | None:
    """Why chunk file ``path`` is not the finished chunk its log ``entry`` describes (None: it is).

    Without a log entry (a folder written before checksums were logged) the
    file must decode completely and hold ``rows`` rows.
    """
    if entry is not None:
        if entry.get("rows") != rows:
            return f"it holds {entry.get('rows')} rows, the chunk has {rows}"
        if _known_digest(path) == entry.get("sha256"):
            return None
        try:
            digest, size = file_sha256(path)
        except OSError as e:
            return f"unreadable ({e.strerror or e})"
        if size != entry.get("bytes") or digest != entry.get("sha256"):
            return f"its SHA-256 differs from the one recorded in {CHUNK_LOG}"
        _remember(path, digest)
        return None
    try:
        n = pq.read_table(path).num_rows
    except Exception as e:  # noqa: BLE001 - any decoding error means "not a finished chunk"
        return f"it does not decode ({type(e).__name__}: {' '.join(str(e).split())[:120]})"
    return None if n == rows else f"it holds {n} rows, the chunk has {rows}"


def _check_manifest(folder: Path, defn: ScanDefinition) -> bool:
    """True if ``folder`` holds this scan's manifest, False if none; ScanMismatchError if another scan's."""
    mpath = folder / MANIFEST
    if not mpath.exists():
        return False
    try:
        have = json.loads(mpath.read_text())["definition"]
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise ScanMismatchError(f"{str(folder)!r}: unreadable scan manifest {MANIFEST} ({e})") from None
    want = defn.to_dict()
    if json.dumps(have, sort_keys=True) != json.dumps(want, sort_keys=True):
        diffs = describe_differences(have, want)
        shown = "; ".join(diffs[:4]) + (f"; and {len(diffs) - 4} more" if len(diffs) > 4 else "")
        raise ScanMismatchError(
            f"{str(folder)!r} holds a different scan ({shown}). "
            "Use another --out folder, or delete this one to start over."
        )
    return True


def _check_empty(folder: Path) -> None:
    """FileExistsError unless ``folder`` (holding no manifest) has no data files (hidden files do not count)."""
    if any(not p.name.startswith(".") for p in folder.iterdir()):
        raise FileExistsError(
            f"{str(folder)!r} is not empty and holds no dicetrace scan ({MANIFEST} missing): use another folder"
        )


def prepare_folder(folder, defn: ScanDefinition) -> set[int]:
    """Create or check the scan folder; return the chunks already finished (and verified).

    Call it holding the folder's lock (:func:`scan` does).  Raises
    :class:`ScanMismatchError` when the folder holds another scan, and
    FileExistsError when it holds files that are not a dicetrace scan.
    Leftover temporary files of interrupted writes are removed.  Every
    finished chunk is checked against its logged checksum; a damaged one
    (or one with the wrong number of rows) is deleted, to be recomputed,
    with a :class:`ScanWarning` naming it.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    if not _check_manifest(folder, defn):
        _check_empty(folder)
        manifest = {
            "format": defn.to_dict()["format"],
            "dicetrace_version": _version(),
            "definition": defn.to_dict(),
            "n_ics": defn.size,
            "n_chunks": defn.n_chunks,
            "chunk_log": CHUNK_LOG,
            "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        }
        _atomic_write_text(folder / MANIFEST, json.dumps(manifest, indent=1, sort_keys=True))
    for p in folder.glob(".part-*.tmp"):
        p.unlink(missing_ok=True)
    log = read_chunk_log(folder)
    done = set()
    for c, p in chunk_files(folder).items():
        if c >= defn.n_chunks:
            continue
        start, stop = defn.chunk_range(c)
        why = verify_chunk(p, log.get(c), stop - start)
        if why is None:
            if c not in log:  # adopt a chunk of a folder written before checksums were logged
                digest, size = file_sha256(p)
                _append_chunk_log(folder, {"chunk": c, "file": p.name, "rows": stop - start, "bytes": size,
                                           "sha256": digest})
            done.add(c)
        else:
            warnings.warn(f"scan chunk {str(p)!r} is damaged ({why}): recomputing it", ScanWarning, stacklevel=3)
            p.unlink(missing_ok=True)
    return done


def write_chunk(folder, defn: ScanDefinition, c: int, table: pa.Table) -> Path:
    """Write chunk ``c`` atomically (temporary name, checksum logged, then rename).

    A write that fails (say, on a full disk) leaves no temporary file and
    raises :class:`~dicetrace.sinks._common.OutputError` naming the chunk;
    the chunks finished before are kept.
    """
    folder = Path(folder)
    path = folder / part_name(c)
    tmp = path.with_name(f".{path.name}.{os.getpid()}-{uuid.uuid4().hex[:8]}.tmp")
    try:
        with open(tmp, "wb") as f:  # our own handle: closed on any error (a full disk), never left to the GC
            pq.write_table(
                _with_metadata(table, chunk_metadata(defn, c)),
                f,
                compression="zstd",
                use_dictionary=DICTIONARY_COLUMNS,  # high-cardinality columns gain nothing and cost time
            )
            f.flush()
            os.fsync(f.fileno())
        digest, size = file_sha256(tmp)
        _append_chunk_log(folder, {"chunk": c, "file": path.name, "rows": table.num_rows, "bytes": size,
                                   "sha256": digest})
        os.replace(tmp, path)
        _remember(path, digest)
    except OSError as e:
        if isinstance(e, OutputError):
            raise
        reason = os.strerror(e.errno) if e.errno else " ".join(str(e).split())
        raise OutputError(
            f"cannot write scan chunk {str(path)!r}: {reason} (the finished chunks are kept: "
            "free space and re-run the same scan to resume)"
        ) from None
    finally:
        remove_quietly(tmp)
    return path


class _FolderLock:
    """The folder's writer lock (``filelock``); refuses in one line after ``wait`` seconds."""

    def __init__(self, folder: Path, wait: float):
        from filelock import FileLock

        self.folder, self.wait = folder, wait
        self.lock = FileLock(str(folder / LOCK), timeout=wait)

    def __enter__(self):
        from filelock import Timeout

        try:
            self.lock.acquire()
        except Timeout:
            raise ScanBusyError(
                f"another dicetrace scan is writing into {str(self.folder)!r} (it holds {LOCK}); "
                f"waited {self.wait:g} s: let it finish (then re-run: finished chunks are skipped), "
                "or wait for it (--wait SECONDS)"
            ) from None
        return self

    def __exit__(self, *exc):
        self.lock.release()


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
            transient=True,
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


_SPACES = (Grid, Sample, Points)


def _definition(space, config, chunk, options) -> ScanDefinition:
    if isinstance(space, ScanDefinition):
        if config is not None or any(v is not None for v in options.values()):
            raise ValueError("give a ScanDefinition or a space with its configuration, not both")
        return space
    if not isinstance(space, _SPACES):
        raise TypeError(
            f"space must be a Grid, Sample or Points (dicetrace.ics) or a ScanDefinition, not {type(space).__name__}"
        )
    return ScanDefinition(space, resolve_config(config, **options), chunk)


def _check_dask(dask) -> None:
    if dask is None or isinstance(dask, bool) or isinstance(dask, str):
        if isinstance(dask, str):
            check_scheduler_address(dask)
        return
    try:
        from dask.distributed import Client
    except ImportError:  # pragma: no cover
        Client = ()
    if not isinstance(dask, Client):
        raise TypeError(f"dask must be None, True, a scheduler address or a dask.distributed.Client, not {type(dask).__name__}")


_SCHEMES = ("tcp", "tls", "inproc", "ucx", "ws", "wss")


def check_scheduler_address(address: str) -> tuple[str, str, int | None]:
    """(scheme, host, port) of a Dask scheduler address, or ValueError naming it."""
    if not isinstance(address, str):
        raise TypeError(f"the scheduler address must be a string, not {type(address).__name__}")
    text = address.strip()
    scheme, sep, rest = text.partition("://")
    if not sep:
        scheme, rest = "tcp", text
    bad = ValueError(f"scheduler address {address!r} is not SCHEME://HOST:PORT (e.g. tcp://127.0.0.1:8786)")
    if scheme not in _SCHEMES or not rest or any(c.isspace() for c in rest) or "/" in rest:
        raise bad
    if scheme == "inproc":
        return scheme, rest, None
    if rest.startswith("["):  # [IPv6]:port
        host, _, port_text = rest[1:].partition("]")
        port_text = port_text[1:] if port_text.startswith(":") else port_text
    else:
        host, _, port_text = rest.rpartition(":") if ":" in rest else (rest, "", "")
    if not host:
        raise bad
    if not port_text:
        raise ValueError(f"scheduler address {address!r} needs a port (e.g. {scheme}://{host}:8786)")
    if not port_text.isdigit() or not 0 < int(port_text) < 65536:
        raise bad
    return scheme, host, int(port_text)


def _connect(address: str, timeout: float):
    """A Client of the scheduler at ``address``, within ``timeout`` seconds, or :class:`SchedulerError`."""
    import socket

    from dask.distributed import Client

    scheme, host, port = check_scheduler_address(address)
    deadline = time.monotonic() + timeout
    if scheme in ("tcp", "tls") and port is not None:
        try:
            with socket.create_connection((host, port), timeout=timeout):
                pass
        except OSError as e:
            why = "timed out" if isinstance(e, TimeoutError) else (e.strerror or str(e))
            raise SchedulerError(
                f"cannot reach the Dask scheduler at {address!r} within {timeout:g} s: {why}"
            ) from None
    last = None
    for _attempt in range(2):
        left = deadline - time.monotonic()
        if left <= 0.5:
            break
        try:
            return _client_within(Client, address, left, timeout)
        except AssertionError as e:
            # distributed's handshake can trip when the scheduler is still winding
            # down another client's futures: try again, within the same deadline.
            last = e
            time.sleep(min(0.5, max(0.0, deadline - time.monotonic() - 0.5)))
        except SchedulerError:
            raise
        except OSError as e:
            raise SchedulerError(
                f"no answer from the Dask scheduler at {address!r} within {timeout:g} s "
                f"({' '.join(str(e).split())[:160]})"
            ) from None
        except Exception as e:  # noqa: BLE001 - a server that is not a Dask scheduler fails in many ways
            raise SchedulerError(
                f"{address!r} does not answer as a Dask scheduler (the handshake failed: "
                f"{type(e).__name__}: {' '.join(str(e).split())[:160]})"
            ) from None
    raise SchedulerError(f"the Dask scheduler at {address!r} did not complete the handshake within {timeout:g} s"
                         + (f" ({type(last).__name__})" if last is not None else ""))


def _client_within(Client, address: str, left: float, timeout: float):
    """``Client(address)``, given at most ``left`` seconds: distributed's own timeout does not cover a
    server that accepts the connection and then says nothing, so the handshake runs in a thread."""
    import threading

    box: dict = {}

    def make() -> None:
        try:
            box["client"] = Client(address, timeout=left)
        except BaseException as e:  # noqa: BLE001 - handed to the caller
            box["error"] = e

    th = threading.Thread(target=make, name="dicetrace-dask-connect", daemon=True)
    th.start()
    th.join(left + 0.5)
    if th.is_alive():
        raise SchedulerError(f"no answer from the Dask scheduler at {address!r} within {timeout:g} s "
                             "(the server accepted the connection but did not complete the handshake)")
    if "error" in box:
        raise box["error"]
    return box["client"]


def _open_dask(dask, n_workers, timeout: float | None = None):
    """(client, closers) for ``dask``: True (a LocalCluster), an address (within ``timeout``, default
    ``DASK_CONNECT_TIMEOUT_S``), or a Client."""
    from dask.distributed import Client, LocalCluster

    if isinstance(dask, Client):
        return dask, []
    if isinstance(dask, str):
        client = _connect(dask, DASK_CONNECT_TIMEOUT_S if timeout is None else timeout)
        return client, [client]
    try:
        cluster = LocalCluster(
            n_workers=n_workers or os.cpu_count() or 1, threads_per_worker=1, processes=True, dashboard_address=":0"
        )
    except Exception as e:  # noqa: BLE001
        raise SchedulerError(f"could not start a local Dask cluster: {type(e).__name__}: {' '.join(str(e).split())[:160]}") from None
    client = Client(cluster)
    return client, [client, cluster]


def _iter_dask(defn: ScanDefinition, todo: Iterable[int], client, threads) -> Iterator[tuple[int, pa.Table]]:
    """Chunks on a Dask cluster as they complete, with a bounded number of tasks in flight."""
    from dask.distributed import as_completed

    d = defn.to_dict()
    run = uuid.uuid4().hex[:8]
    try:
        width = max(4, 2 * sum(client.nthreads().values()))
    except Exception:  # noqa: BLE001
        width = 16
    it = iter(todo)

    def submit(c):
        return client.submit(_chunk_task, d, c, threads or 1, key=f"dicetrace-scan-{run}-{c}", pure=False)

    live = {submit(c) for c in itertools.islice(it, width)}
    try:
        ac = as_completed(list(live))
        for fut in ac:
            c, table = fut.result()
            live.discard(fut)
            fut.release()
            nxt = next(it, None)
            if nxt is not None:
                f2 = submit(nxt)
                live.add(f2)
                ac.add(f2)
            yield c, table
    finally:
        for f in live:
            f.cancel()


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
    _check_int(threads, "threads", 1)
    _check_int(n_workers, "n_workers", 1)
    _check_dask(dask)
    todo = range(defn.n_chunks) if chunks is None else chunks
    if dask:
        client, closers = _open_dask(dask, n_workers)
        try:
            yield from _iter_dask(defn, todo, client, threads)
        finally:
            for x in closers:
                x.close()
        return
    for c in todo:
        yield c, compute_chunk(defn, c, threads=threads)


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

    Returns
    -------
    pyarrow.Table (``out`` is None: sorted by ``ic_id``) or :class:`ScanReport`.

    Raises
    ------
    TypeError, ValueError
        A bad argument (named), before anything is computed or written.
    ScanMismatchError, FileExistsError
        ``out`` holds another scan, or files that are not a scan.
    ScanBusyError
        Another scan is writing into ``out``.
    SchedulerError
        The Dask scheduler cannot be reached or is not one.
    dicetrace.sinks._common.OutputError
        ``out`` cannot be created or written (the message names it); on a
        full disk the chunks finished so far are kept.
    """
    defn = _definition(space, config, chunk, options)
    _check_scan_args(out, threads, n_workers, max_chunks, wait, progress, dask)
    _check_space_finite(defn)
    t0 = time.perf_counter()
    if out is None:
        tables = [t for _, t in iter_scan(defn, threads=threads, dask=dask, n_workers=n_workers)]
        table = pa.concat_tables(tables)
        if dask:
            table = table.sort_by("ic_id")
        return _with_metadata(table, {"dicetrace_version": _version(), "scan": defn.to_dict(),
                                      "config": defn.config.as_dict(), "l_convention": defn.config.preset.l_convention})
    folder = output_folder(out, what="scan folder")
    if folder.is_dir() and not _check_manifest(folder, defn):  # refuse at once, without waiting for a lock
        _check_empty(folder)
    client, closers = (None, [])
    if dask:
        client, closers = _open_dask(dask, n_workers)
    try:
        created = make_folders(folder)
        had_lock = (folder / LOCK).exists()
        try:
            with _FolderLock(folder, float(wait)):
                return _run_into(folder, defn, created, t0, threads=threads, progress=progress, client=client,
                                 max_chunks=max_chunks)
        except BaseException:
            if not (folder / MANIFEST).exists():  # refused before anything was written: leave nothing behind
                if not had_lock:
                    remove_quietly(folder / LOCK)
                remove_folders(created)
            raise
    finally:
        for x in closers:
            x.close()


def _run_into(folder: Path, defn: ScanDefinition, created, t0: float, *, threads, progress, client, max_chunks):
    done = prepare_folder(folder, defn)
    todo: Iterable[int] = (c for c in range(defn.n_chunks) if c not in done)
    if max_chunks is not None:
        todo = itertools.islice(todo, max_chunks)
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

    chunks = _iter_dask(defn, todo, client, threads) if client is not None else (
        (c, compute_chunk(defn, c, threads=threads)) for c in todo
    )
    try:
        # A writer thread encodes and writes chunk c while the kernel (which
        # releases the GIL) computes chunk c+1.  On an interrupt the chunks
        # already computed are still written (the pool's exit waits for them).
        with ThreadPoolExecutor(max_workers=1, thread_name_prefix="dicetrace-scan-writer") as writer:
            for c, table in chunks:
                pending.append((writer.submit(write_chunk, folder, defn, c, table), table.num_rows))
                settle(block=len(pending) > 1)
            settle(block=True)
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
    )


# -- estimating -------------------------------------------------------------------------------


#: Calibration: ICs sampled across the space, and the steps each may take.
CALIBRATION_ICS = 48
CALIBRATION_STEPS = 20_000
#: Slowest step of any integrator, s (a pessimistic bound used to skip calibrating tiny scans).
SLOWEST_STEP_S = 2e-6


@dataclass(frozen=True)
class ScanEstimate:
    """What a scan run would cost, before it starts (:func:`estimate_scan`).

    ``seconds`` is the estimated wall time of this run on ``threads``
    threads (None when the run is too small to be worth timing: at most
    ``seconds_bound``); ``upper`` says the estimate assumes that the sampled
    throws which had not ended within the calibration's steps run to the
    time cap.  ``bytes`` is the estimated size on disk of the new chunks.
    """

    n_ics: int
    n_chunks: int
    chunks_todo: int
    ics_todo: int
    bytes: int
    free_bytes: int | None
    chunk_memory: int
    threads: int
    seconds: float | None
    seconds_bound: float
    upper: bool = False

    def describe(self) -> str:
        t = self.seconds if self.seconds is not None else self.seconds_bound
        when = f"{'at most ' if self.seconds is None or self.upper else 'about '}{human_seconds(t)}"
        free = "" if self.free_bytes is None else f", {human_bytes(self.free_bytes)} free"
        return (f"{self.ics_todo:,} ICs in {self.chunks_todo:,} chunks to compute (of {self.n_ics:,}): "
                f"{when} on {self.threads} thread(s), about {human_bytes(self.bytes)} on disk{free}")


def human_seconds(s: float) -> str:
    if s < 90:
        return f"{s:.0f} s"
    if s < 5400:
        return f"{s / 60:.0f} min"
    if s < 2 * 86400:
        return f"{s / 3600:.1f} h"
    if s < 2 * 365 * 86400:
        return f"{s / 86400:.0f} days"
    return f"{s / (365.25 * 86400):.3g} years"


def estimate_scan(defn: ScanDefinition, out=None, *, threads: int | None = None, max_chunks: int | None = None,
                  calibrate: bool = True) -> ScanEstimate:
    """Estimate a scan run (time, disk, memory per chunk) before starting it.

    Counts the chunks ``out`` already holds (by name; nothing is verified or
    written), then, unless the run is certainly short, times up to
    ``CALIBRATION_ICS`` ICs spread over the space with the scan's
    configuration, each limited to ``CALIBRATION_STEPS`` steps (a throw not
    ended by then is counted at the full time cap: the estimate is then an
    upper one).
    """
    import numba

    if not isinstance(defn, ScanDefinition):
        raise TypeError(f"defn must be a ScanDefinition, not {type(defn).__name__}")
    _check_int(threads, "threads", 1)
    _check_int(max_chunks, "max_chunks", 0)
    n_done = 0
    if out is not None and Path(out).is_dir() and (Path(out) / MANIFEST).exists():
        n_done = sum(1 for c in chunk_files(out) if c < defn.n_chunks)
    chunks_todo = defn.n_chunks - n_done
    if max_chunks is not None:
        chunks_todo = min(chunks_todo, max_chunks)
    ics_todo = min(defn.size, chunks_todo * defn.chunk)  # at most: the last chunk may be short
    nthreads = threads or numba.get_num_threads()
    max_steps = defn.config.numerics.max_steps
    bound = ics_todo * max_steps * SLOWEST_STEP_S / nthreads
    free = free_bytes(_existing_parent(Path(out) if out is not None else Path.cwd()))
    est = ScanEstimate(
        n_ics=defn.size, n_chunks=defn.n_chunks, chunks_todo=chunks_todo, ics_todo=ics_todo,
        bytes=ics_todo * BYTES_PER_IC + chunks_todo * BYTES_PER_CHUNK, free_bytes=free, chunk_memory=min(defn.chunk, defn.size) * MEMORY_PER_IC,
        threads=nthreads, seconds=None, seconds_bound=bound,
    )
    if not calibrate or bound <= 30.0 or ics_todo == 0:
        return est
    n = min(CALIBRATION_ICS, defn.size)
    ids = sorted({int(round(v)) for v in np.linspace(0, defn.size - 1, n)})
    ics = np.concatenate([defn.space.block(i, i + 1).ics for i in ids]).reshape(-1, 6)
    num = defn.config.numerics
    cal_steps = min(max_steps, CALIBRATION_STEPS)
    cal = replace(defn.config, numerics=replace(num, t_max_s=min(num.t_max_s, cal_steps * num.dt_s)))
    conv = defn.space.slice.l_convention
    simulate_batch(ics[:1], config=replace(cal, numerics=replace(num, t_max_s=num.dt_s)), l_convention=conv,
                   threads=1)  # load the compiled kernel before timing
    t = time.perf_counter()
    res = simulate_batch(ics, config=cal, l_convention=conv, threads=1)
    wall = time.perf_counter() - t
    steps = res.steps.astype(np.float64)
    capped = (steps >= cal.numerics.max_steps) & (cal.numerics.max_steps < max_steps)
    full = np.where(capped, float(max_steps), steps)
    per_ic = wall / len(ids) * (full.sum() / max(steps.sum(), 1.0))
    return replace(est, seconds=ics_todo * per_ic / nthreads, upper=bool(capped.any()))


def _existing_parent(p: Path) -> Path:
    p = p.absolute()
    while not p.exists() and p != p.parent:
        p = p.parent
    return p
