"""The scan dataset folder: manifest, chunk files, their checksum log, and the writer's lock.

A scan folder holds the manifest ``_scan.parquet`` and the subfolder
``rolls/`` with one Parquet file per finished chunk, ``part-NNNNNN.parquet``
and nothing else.  The manifest is a Parquet file with the rolls table's
columns and no rows; its key-value metadata holds the scan definition
(``dicetrace.scan``: the definition, the dicetrace version) and the chunk log
(``dicetrace.chunks``: per finished chunk its file, rows, size and SHA-256).
So the folder holds nothing but Parquet files of one schema (and the empty
lock file): every reader reads the scan folder itself as the rolls table, the
manifest adding no row -- Polars too, which reads every non-empty file under a
folder and refuses a folder with files of two extensions.  Each chunk is
written under a hidden temporary name beside the manifest, renamed into
``rolls/``, and its checksum logged in the manifest (rewritten atomically, at
most once a second while a scan runs, and as it ends).  So a
Ctrl-C or a kill loses at most the chunks in flight; running the same scan
again verifies the finished chunks against their checksums (recomputing, with
a :class:`ScanWarning`, any that are damaged), skips the good ones and ends
with exactly one row per IC.  The folder holds what the manifest lists:
anything else in ``rolls/`` (or a chunk file beside the manifest) is refused
by name (:class:`ForeignFileError`), a chunk not listed yet is adopted only
once its content is checked to be the chunk's, and dicetrace's readers read
only the listed chunks, each checked against its checksum and against the
definition in its own metadata.  A different definition against an existing
folder is refused (:class:`ScanMismatchError`, compared by value and naming
what differs), never mixed in.  One writer at a time: taking the folder's lock
(``.dicetrace-scan.lock``, via ``filelock``) is the first thing a scan does
to the folder (it makes the folder to hold it), and it holds the lock while
it writes; a second one waits at most ``wait`` seconds, then refuses
(:class:`ScanBusyError`), touching nothing.  Nothing removes a lock it does
not hold: a scan that fails before its first chunk reached a new folder removes
the manifest it wrote, its own lock (holding it) and the folders it made.

Every reader reads the folder as it is: ``polars.scan_parquet("scan/")``,
``pandas.read_parquet("scan")``, DuckDB's ``read_parquet('scan/**/*.parquet')``
and ``pyarrow.dataset.dataset("scan")`` (pandas and pyarrow skip the manifest:
they skip names starting with ``_`` or ``.``).  While a scan writes, its
temporary files lie in the folder, which Polars refuses: ``rolls/`` alone
holds only finished parts, and every reader reads it at any time.

Folders of older dicetrace versions are still read: a JSON manifest
``_scan.json`` with the chunk log ``_scan.chunks.jsonl`` beside it, and parts
beside the manifest rather than in ``rolls/``; the next scan into such a
folder turns it into this layout.

The chunk files themselves (names, listing, checksums, the checks of
``rolls/``) are :mod:`dicetrace.scan.chunk_files`'s.
"""
from __future__ import annotations

import functools
import itertools
import json
import os
import threading
import time
import uuid
import warnings
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from filelock import FileLock, Timeout

import dicetrace
from dicetrace.batch_chunks import DEFAULT_CAP
from dicetrace.ics import Grid, Sample
from dicetrace.scan.chunk_files import (
    MANIFEST,
    METADATA_KEY,
    ROLLS_DIR,
    check_beside,
    check_rolls,
    chunk_files,
    chunk_identity,
    file_sha256,
    foreign_file,
    move_legacy_parts,
    part_name,
    remember_digest,
    verify_chunk,
    verify_unlogged,
)
from dicetrace.scan.chunk_files import ForeignFileError, rolls_dir  # noqa: F401 (re-exported: users import them from here)
from dicetrace.devices import DeviceError, resolve_device
from dicetrace.scan.definition import ScanDefinition, describe_differences, device_kind, as_written_now
from dicetrace.simulate import simulate_batch
from dicetrace.sinks._common import OutputError, make_folders, remove_quietly
from dicetrace.tables import rolls_table

#: The manifest (MANIFEST): a Parquet file of the rolls table's schema with no rows; its key-value metadata holds
#: the scan definition (MANIFEST_KEY) and the chunk log (CHUNK_LOG_KEY).
MANIFEST_KEY = b"dicetrace.scan"
#: The manifest's chunk log: chunk index → its file, rows, bytes and sha256 (a JSON object).
CHUNK_LOG_KEY = b"dicetrace.chunks"
#: The JSON manifest and its chunk log (one JSON line per finished chunk) of folders of an older dicetrace.
LEGACY_MANIFEST = "_scan.json"
LEGACY_CHUNK_LOG = "_scan.chunks.jsonl"
#: The folder's writer lock (held by the one scan writing into it).
LOCK = ".dicetrace-scan.lock"
DICTIONARY_COLUMNS = ["preset", "integrator", "status", "outcome", "dt_s", "k"]


class ScanMismatchError(ValueError):
    """The folder holds a scan with a different definition."""


class DeviceMismatchError(ScanMismatchError):
    """The folder holds the same scan run on another device (a GPU's throws may differ from the CPU's by rounding)."""


class ScanBusyError(RuntimeError):
    """Another scan holds the folder's writer lock."""


class CorruptChunkError(ValueError):
    """A chunk file does not match the checksum recorded when it was written (the message names the file)."""


class ScanWarning(UserWarning):
    """Something a scan repaired on the way (a damaged chunk recomputed)."""


def _version() -> str:
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
    """Refuse a space whose ICs overflow: the corners of a window or box (an IC is affine in its coordinates), or every
    point; a space of throws from their own poses, a throw that would start below the table (``space.check``)."""
    space = defn.space
    if defn.posed:
        space.check(defn.config)
        return
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


@functools.cache
def _resolved(label: str):
    """The device a scan's label names, resolved once per process (a worker resolves its own)."""
    return resolve_device(device_kind(label))


def compute_chunk(defn: ScanDefinition, c: int, *, threads: int | None = None, cap: int = DEFAULT_CAP) -> pa.Table:
    """The rolls table of chunk ``c`` of a scan (its metadata: the batch's, with the device it ran on).

    ``threads``: numba threads for this chunk (None: numba's current setting).
    The rows do not depend on it, nor on the chunk size: every IC is the
    serial kernel's result for that IC.  The chunk runs on the definition's
    device, resolved here (on a Dask worker: by the worker): a
    :class:`~dicetrace.devices.DeviceError` where this machine has no GPU
    for a GPU scan, or where its GPU is another than the scan's.
    """
    start, stop = defn.chunk_range(c)
    blk = defn.block(start, stop)
    poses = {"orientations": blk.orientations, "heights_cm": blk.heights_cm} if defn.posed else {}
    batch = simulate_batch(
        blk.ics, config=defn.config, l_convention=defn.l_convention, threads=threads, cap=cap,
        device=_resolved(defn.device), record=defn.record, **poses,
    )
    if batch.device != defn.device:
        raise DeviceError(f"chunk {c} ran on {batch.device}, the scan runs on {defn.device}: "
                          "one scan runs on one device (its throws may differ by rounding from one to another)")
    if defn.posed:  # each pose as given, not read back off its matrix: a replay makes the same matrix of it
        batch.orientations = blk.orientations
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
        "device": defn.device,
        "die": defn.die,
        "chunk_index": c,
        "ic_range": [start, stop],
    }


def _with_metadata(table: pa.Table, meta: dict) -> pa.Table:
    md = dict(table.schema.metadata or {})
    md[METADATA_KEY] = json.dumps(meta, sort_keys=True).encode()
    return table.replace_schema_metadata(md)


# -- the dataset folder ----------------------------------------------------------------------


def has_manifest(folder) -> bool:
    """True if ``folder`` holds a scan manifest (this version's, or an older dicetrace's JSON one)."""
    return (Path(folder) / MANIFEST).is_file() or (Path(folder) / LEGACY_MANIFEST).is_file()


def _manifest_metadata(path: Path) -> dict:
    """The key-value metadata of the Parquet manifest at ``path``."""
    return pq.read_schema(path).metadata or {}


def read_manifest(folder) -> dict:
    """The scan folder's manifest: its definition (``"definition"``), dicetrace version, size and creation time.

    FileNotFoundError where ``folder`` holds no scan (or does not exist), NotADirectoryError where it is a file
    (the manifest itself included: the scan is its folder), ValueError where the manifest cannot be read.
    """
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        hint = f": give its folder, {str(folder.parent)!r}" if folder.name in (MANIFEST, LEGACY_MANIFEST) else ""
        raise NotADirectoryError(f"{str(folder)!r} is a file, not a dicetrace scan folder{hint}")
    p = folder / MANIFEST
    if not p.is_file():
        p = folder / LEGACY_MANIFEST
        if not p.is_file():
            raise FileNotFoundError(f"{str(folder)!r} is not a dicetrace scan folder (no {MANIFEST})")
    try:
        return json.loads(_manifest_metadata(p)[MANIFEST_KEY] if p.name == MANIFEST else p.read_text())
    except (OSError, ValueError, KeyError, pa.ArrowException) as e:
        raise ValueError(f"{str(p)!r}: unreadable scan manifest ({' '.join(str(e).split())})") from None


def _write_manifest(folder: Path, manifest: dict, log: dict[int, dict]) -> None:
    """Write the Parquet manifest atomically: the rolls schema, no rows, ``manifest`` and ``log`` as metadata."""
    path = folder / MANIFEST
    tmp = folder / f".{MANIFEST}.{os.getpid()}-{uuid.uuid4().hex[:8]}.tmp"
    meta = {
        MANIFEST_KEY: json.dumps(manifest, indent=1, sort_keys=True).encode(),
        CHUNK_LOG_KEY: json.dumps({str(c): log[c] for c in sorted(log)}, sort_keys=True).encode(),
    }
    try:
        with open(tmp, "wb") as f:
            schema = ScanDefinition.from_dict(manifest["definition"]).schema
            pq.write_table(schema.empty_table().replace_schema_metadata(meta), f, compression="zstd")
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    finally:
        remove_quietly(tmp)


def read_chunk_log(folder) -> dict[int, dict]:
    """The chunk log of a scan folder: chunk index → its entry (file, rows, bytes, sha256).

    It is read from the manifest's metadata; for a folder of an older
    dicetrace, from ``_scan.chunks.jsonl``, where a torn last line (a write
    killed half way) is skipped: that chunk's file was never renamed into place.
    Only well-formed entries are returned (:func:`read_chunk_log_checked`
    says what else the log holds).
    """
    return read_chunk_log_checked(folder)[0]


def read_chunk_log_checked(folder) -> tuple[dict[int, dict], dict[str, str]]:
    """The chunk log's well-formed entries (see :func:`read_chunk_log`), and what is wrong with the others: its key
    (the chunk index as written, or ``"*"`` for a log that is not a JSON object at all) → why, in a few words.

    A broken entry lists nothing: its chunk file, if any, is checked by its
    content as one the log does not list.  A log that cannot be read at all
    lists nothing (``{"*": why}``).
    """
    p = Path(folder) / MANIFEST
    broken: dict[str, str] = {}
    if p.is_file():
        try:
            raw = json.loads(_manifest_metadata(p).get(CHUNK_LOG_KEY, b"{}"))
        except (OSError, ValueError, pa.ArrowException) as e:
            return {}, {"*": f"unreadable ({' '.join(str(e).split())[:120]})"}
        if not isinstance(raw, dict):
            return {}, {"*": f"not a JSON object but {_shown(raw)}"}
        entries = {}
        for key, e in raw.items():
            why = _entry_problem(key, e)
            if why is None:
                entries[int(key)] = e
            else:
                broken[str(key)] = why
        return entries, broken
    entries: dict[int, dict] = {}
    try:
        with open(Path(folder) / LEGACY_CHUNK_LOG) as f:
            for line in f:
                try:
                    e = json.loads(line)
                    key = e["chunk"]
                except (ValueError, KeyError, TypeError):
                    continue
                if _entry_problem(key, e) is None:
                    entries[int(key)] = e
    except FileNotFoundError:
        pass
    return entries, broken


def _shown(value) -> str:
    text = json.dumps(value, default=repr)
    return text if len(text) <= 40 else text[:37] + "..."


def _entry_problem(key, e) -> str | None:
    """Why ``e`` (under ``key`` in the chunk log) is not a chunk-log entry (None: it is one)."""
    if isinstance(key, bool) or not isinstance(key, (int, str)) or not str(key).isdecimal():
        return f"key {_shown(key)} is no chunk index"
    c = int(key)
    if not isinstance(e, dict):
        return f"entry of chunk {c} is not an object but {_shown(e)}"
    for field, kind in (("rows", int), ("bytes", int), ("sha256", str), ("file", str)):
        v = e.get(field)
        if isinstance(v, bool) or not isinstance(v, kind) or (kind is int and v < 0):
            return f"entry of chunk {c} has {field} {_shown(v)}, not {'a count' if kind is int else 'a string'}"
    if "chunk" in e and (isinstance(e["chunk"], bool) or e["chunk"] != c):
        return f"entry of chunk {c} says chunk {_shown(e['chunk'])}"
    return None


def _log_name(folder: Path, path: Path) -> str:
    """A chunk file's name in the chunk log: its path relative to the scan folder, with ``/``."""
    return Path(path).relative_to(folder).as_posix()


#: The chunk log is rewritten at most once a second, and at most 10 % of the time (its size grows with the
#: chunks); the entries in between wait in memory.  A part renamed into rolls/ before its entry was written
#: (a kill in between) is verified on resume by decoding it whole, as in a folder without a chunk log.
LOG_INTERVAL_S = 1.0
_MANIFEST_WRITE = threading.Lock()
_PENDING: dict[Path, list[dict]] = {}
_LAST_LOG: dict[Path, tuple[float, float]] = {}  # folder → (monotonic time of the last rewrite, its cost in s)


def _log_chunks(folder: Path, entries: list[dict], *, force: bool = False) -> None:
    """Add ``entries`` to the manifest's chunk log: rewritten (atomically) now if ``force`` or if it is due.

    Call it holding the folder's lock; :func:`flush_chunk_log` writes what waits.
    """
    key = Path(folder).absolute()
    with _MANIFEST_WRITE:
        pending = _PENDING.setdefault(key, [])
        pending.extend(entries)
        last, cost = _LAST_LOG.get(key, (-float("inf"), 0.0))
        t0 = time.monotonic()
        if not pending or not (force or t0 - last >= max(LOG_INTERVAL_S, 10 * cost)):
            return
        try:
            log = read_chunk_log(folder)
            log.update({int(e["chunk"]): e for e in pending})
            _write_manifest(Path(folder), read_manifest(folder), log)
        except OSError as e:
            reason = os.strerror(e.errno) if e.errno else " ".join(str(e).split())
            raise OutputError(f"cannot write the scan manifest {str(Path(folder) / MANIFEST)!r}: {reason} (the "
                              "finished chunks are kept: free space and re-run the same scan to resume)") from None
        del _PENDING[key]
        t1 = time.monotonic()
        _LAST_LOG[key] = (t1, t1 - t0)


def flush_chunk_log(folder) -> None:
    """Write the chunk-log entries that wait in memory into the manifest (a scan calls it as it ends)."""
    _log_chunks(Path(folder), [], force=True)


def _check_manifest(folder: Path, defn: ScanDefinition) -> bool:
    """True if ``folder`` holds this scan's manifest, False if none; ScanMismatchError if another scan's."""
    if not has_manifest(folder):
        return False
    try:
        have = as_written_now(read_manifest(folder)["definition"])
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise ScanMismatchError(f"{str(folder)!r}: unreadable scan manifest ({e})") from None
    want = defn.to_dict()
    diffs = describe_differences(have, want)  # values, not their text: 0 and 0.0 are one number
    if diffs:
        if isinstance(have, dict) and have.get("device") != want["device"] and \
                not describe_differences({**have, "device": None}, {**want, "device": None}):
            was = str(have.get("device"))
            kind = "" if device_kind(was) == was else f" (device {device_kind(was)!r})"
            raise DeviceMismatchError(
                f"{str(folder)!r} holds this scan run on {was!r}, this run is on {want['device']!r}: one scan runs on "
                f"one device (a GPU's throws may differ from the CPU's by rounding): resume it on {was!r}{kind}, "
                "or use another --out folder")
        shown = "; ".join(diffs[:4]) + (f"; and {len(diffs) - 4} more" if len(diffs) > 4 else "")
        raise ScanMismatchError(
            f"{str(folder)!r} holds a different scan ({shown}). "
            "Use another --out folder, or delete this one to start over."
        )
    return True


def _check_empty(folder: Path) -> None:
    """FileExistsError unless ``folder`` (holding no manifest) has no data files (hidden files do not count).

    A folder whose writer lock another scan holds is that scan's, still
    before its manifest: :class:`ScanBusyError`, as the lock itself says.
    """
    if any(not p.name.startswith(".") for p in folder.iterdir()):
        if _lock_held(folder):
            raise ScanBusyError(
                f"another dicetrace scan is writing into {str(folder)!r} (it holds {LOCK}); let it finish "
                "(then re-run: finished chunks are skipped), or use another --out folder"
            )
        raise FileExistsError(
            f"{str(folder)!r} is not empty and holds no dicetrace scan ({MANIFEST} missing): use another folder"
        )


def _lock_held(folder: Path) -> bool:
    """Whether another process holds ``folder``'s writer lock now (a lock file nobody holds is not a writer)."""
    path = folder / LOCK
    if not path.exists():
        return False
    lock = FileLock(str(path), thread_local=False)
    try:
        lock.acquire(timeout=0)
    except Timeout:
        return True
    except OSError:  # a lock file we cannot open: not ours to judge
        return False
    lock.release()
    return False


def has_chunk_log(folder) -> bool:
    """True if the folder's manifest lists its chunks (this version's, or an older one's ``_scan.chunks.jsonl``).

    Only a folder of a dicetrace older still has no chunk log: its parts
    are read by name.
    """
    return (Path(folder) / MANIFEST).is_file() or (Path(folder) / LEGACY_CHUNK_LOG).is_file()


def check_folder(folder, defn: ScanDefinition) -> None:
    """Refuse an existing folder the scan ``defn`` cannot go into, touching nothing (only reading).

    :class:`ScanMismatchError`: it holds another scan; FileExistsError: it
    holds files but no scan; :class:`ForeignFileError`: ``rolls/`` holds
    something that is none of the scan's chunk files (see :func:`check_rolls`),
    or a chunk file lies beside the manifest (see :func:`check_beside`).
    """
    folder = Path(folder)
    if not folder.is_dir():
        return
    if not _check_manifest(folder, defn):
        _check_empty(folder)
    if (folder / MANIFEST).is_file():
        check_beside(folder, read_chunk_log(folder))
    check_rolls(folder, defn)


def prepare_folder(folder, defn: ScanDefinition) -> set[int]:
    """Create or check the scan folder; return the chunks already finished (and verified).

    Call it holding the folder's lock (:func:`scan` does).  Raises
    :class:`ScanMismatchError` when the folder holds another scan (the
    definitions compared by value, the first fields that differ named),
    FileExistsError when it holds files that are not a dicetrace scan, and
    :class:`ForeignFileError` (before changing anything) naming a file
    that cannot be the scan's: in ``rolls/`` another name, a folder, a
    chunk file the manifest does not list that is not the scan's own chunk
    (a copy of another chunk, another scan's, one without the metadata
    every chunk carries), or a listed chunk whose own metadata or columns
    say it belongs to another scan (a manifest edited by hand); beside the
    manifest, a chunk file (:func:`check_beside`).  A chunk the log does
    not list is adopted only once its columns, ``ic_id``s, grid indices,
    slice coordinates and metadata are the chunk's.

    What it can, it repairs: leftover temporary files of interrupted writes
    are removed; a chunk file the manifest does not list yet (a kill
    between its rename and the log's next rewrite) is adopted once checked;
    a chunk-log entry that is no entry (not an object, a count that is not
    an integer) lists nothing, its chunk file checked as an unlisted one and
    its entry written anew, with one :class:`ScanWarning`; a listed chunk
    that no longer matches its logged checksum (or has the wrong number of
    rows) is deleted, to be recomputed, with a :class:`ScanWarning` naming
    it; a folder of an older dicetrace gets this version's layout (its JSON
    manifest and chunk log become the Parquet manifest).
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    with _MANIFEST_WRITE:  # entries an earlier scan failed to write: their parts are verified below by decoding
        _PENDING.pop(folder.absolute(), None)
        _LAST_LOG.pop(folder.absolute(), None)
    check_folder(folder, defn)  # refusals first: nothing is changed before them
    listed = has_chunk_log(folder)  # before a JSON manifest is converted: without a chunk log parts go by name
    log, broken = read_chunk_log_checked(folder)
    if broken:
        first = next(iter(broken.values()))
        warnings.warn(f"the chunk log in {str(folder / MANIFEST)!r} is broken ({first}"
                      + (f"; and {len(broken) - 1} more entries" if len(broken) > 1 else "")
                      + "): the chunk files it does not list are checked by their content", ScanWarning, stacklevel=3)
    done, adopted, damaged, foreign = set(), [], [], []
    for c, p in chunk_files(folder).items():
        if c >= defn.n_chunks:
            continue
        start, stop = defn.chunk_range(c)
        if c in log:
            why = verify_chunk(p, log[c], stop - start)
            if why is not None:
                damaged.append((p, why))
                continue
            why = chunk_identity(p, defn, c)  # the file is the one logged: its footer says whose it is
            if why is None:
                done.add(c)
            else:
                foreign.append((p, f"is listed in {MANIFEST}, but is not chunk {c} of the scan it defines ({why})"))
            continue
        why = verify_unlogged(p, defn, c)
        if why is None:  # the scan's own chunk, not logged yet (or a folder written before checksums were logged)
            digest, size = file_sha256(p)
            adopted.append({"chunk": c, "file": f"{ROLLS_DIR}/{part_name(c)}", "rows": stop - start, "bytes": size,
                            "sha256": digest})
            done.add(c)
        elif listed:
            unlisted = "has a broken entry in" if str(c) in broken or "*" in broken else "is not listed in"
            foreign.append((p, f"{unlisted} {MANIFEST} and is not the scan's own chunk ({why})"))
        else:
            damaged.append((p, why))
    if foreign:
        (p, why), more = foreign[0], len(foreign) - 1
        raise foreign_file(p, folder, why + (f"; and {more} more such file(s)" if more else ""))
    if not has_manifest(folder):
        manifest = {
            "format": defn.to_dict()["format"],
            "dicetrace_version": _version(),
            "definition": defn.to_dict(),
            "die": defn.die,
            "n_ics": defn.size,
            "n_chunks": defn.n_chunks,
            "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        }
        _write_manifest(folder, manifest, {})
    elif not (folder / MANIFEST).is_file():  # an older dicetrace's JSON manifest and chunk log: convert them
        manifest = read_manifest(folder)
        manifest.pop("chunk_log", None)
        _write_manifest(folder, manifest, log)
    for old in (LEGACY_MANIFEST, LEGACY_CHUNK_LOG):
        (folder / old).unlink(missing_ok=True)
    (folder / ROLLS_DIR).mkdir(exist_ok=True)
    move_legacy_parts(folder)
    for p in [*folder.glob(".part-*.tmp"), *folder.glob(f".{MANIFEST}.*.tmp")]:
        p.unlink(missing_ok=True)
    for p, why in damaged:
        if not os.path.lexists(p):  # an older dicetrace's part, moved into rolls/ just above
            p = folder / ROLLS_DIR / p.name
        warnings.warn(f"scan chunk {str(p)!r} is damaged ({why}): recomputing it", ScanWarning, stacklevel=3)
        p.unlink(missing_ok=True)
    _log_chunks(folder, adopted, force=True)
    return done


def write_chunk(folder, defn: ScanDefinition, c: int, table: pa.Table) -> Path:
    """Write chunk ``c`` atomically (temporary name, then rename), and log its checksum (see :func:`_log_chunks`).

    A write that fails (say, on a full disk) leaves no temporary file and
    raises :class:`~dicetrace.sinks._common.OutputError` naming the chunk;
    the chunks finished before are kept.
    """
    folder = Path(folder)
    path = folder / ROLLS_DIR / part_name(c)
    # the temporary file lies beside the manifest: rolls/ only ever holds finished parts
    tmp = folder / f".{path.name}.{os.getpid()}-{uuid.uuid4().hex[:8]}.tmp"
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
        os.replace(tmp, path)
        remember_digest(path, digest)
        _log_chunks(folder, [{"chunk": c, "file": _log_name(folder, path), "rows": table.num_rows, "bytes": size,
                              "sha256": digest}])
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


def _forget_unused_manifest(folder: Path) -> None:
    """Remove the manifest (and ``rolls/``) of a scan that failed before its first chunk reached ``rolls/``.

    Called holding the lock, for a folder that held no manifest before this
    run: the manifest would record a scan that never ran (its device
    included), and refuse the next run of another one.
    """
    rolls = folder / ROLLS_DIR
    try:
        if rolls.is_dir() and any(os.scandir(rolls)):
            return
        remove_quietly(folder / MANIFEST)
        if rolls.is_dir():
            rolls.rmdir()
    except OSError:  # what cannot be removed stays: the next run checks it as it checks any folder
        pass


class _FolderLock:
    """The folder's writer lock (``filelock``): the first thing a scan does to the folder.

    The folder is made (the lock file lives in it) and locked at once;
    after ``wait`` seconds without the lock it refuses in one line,
    removing nothing: the folder and the lock are the holder's.  Nothing
    removes a lock it does not hold.  A scan that ends on an error (or an
    interrupt) while holding the lock of a folder that held no manifest
    before it, and before its first chunk reached ``rolls/``, removes the
    manifest it wrote and ``rolls/``, then the lock file (still holding it:
    a waiter that had opened it sees it unlinked and takes a fresh one) and
    the folders it made, where empty: it leaves no scan that never ran.
    """

    #: A folder removed under a waiting scan (by one that failed before writing anything) is made again at most
    #: this many times.
    RETRIES = 8

    def __init__(self, folder: Path, wait: float):
        self.folder, self.wait = Path(folder), wait
        self.created: list[Path] = []
        self.lock = None

    def __enter__(self):
        deadline = time.monotonic() + self.wait
        for attempt in range(self.RETRIES + 1):
            try:
                self.created += make_folders(self.folder)
            except OSError as e:
                reason = os.strerror(e.errno) if e.errno else " ".join(str(e).split())
                raise OutputError(f"cannot create the scan folder {str(self.folder)!r}: {reason}") from None
            lock = FileLock(str(self.folder / LOCK), thread_local=False)
            try:
                lock.acquire(timeout=max(0.0, deadline - time.monotonic()))
            except Timeout:
                raise ScanBusyError(
                    f"another dicetrace scan is writing into {str(self.folder)!r} (it holds {LOCK}); "
                    f"waited {self.wait:g} s: let it finish (then re-run: finished chunks are skipped), "
                    "or wait for it (--wait SECONDS)"
                ) from None
            except FileNotFoundError:  # the folder went between making and locking it: make it again
                if attempt == self.RETRIES:
                    raise OutputError(f"the scan folder {str(self.folder)!r} keeps disappearing") from None
                continue
            self.lock = lock
            self.had_manifest = has_manifest(self.folder)
            return self

    def __exit__(self, exc_type, *exc):
        try:
            if exc_type is not None and not self.had_manifest:
                _forget_unused_manifest(self.folder)
            if exc_type is not None and not has_manifest(self.folder):  # nothing written: leave nothing behind
                remove_quietly(self.folder / LOCK)  # ours: we hold it
                for d in reversed(self.created):
                    try:
                        d.rmdir()
                    except OSError:
                        break
        finally:
            self.lock.release()
