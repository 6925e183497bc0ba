"""The chunk files of a scan folder's ``rolls/``: their names, the listing, their checksums and their checks.

Each finished chunk ``c`` is one Parquet file ``rolls/part-NNNNNN.parquet``
(:func:`part_name`), and ``rolls/`` holds nothing else.  Here: listing them
(:func:`chunk_files`, counting the parts an older dicetrace left beside the
manifest), checking a file against its chunk-log entry (:func:`verify_chunk`,
SHA-256, remembered per file while its size and mtime hold) or, unlogged,
against the chunk it should be (:func:`verify_unlogged`), and refusing by name
anything in ``rolls/`` that cannot be one of the scan's chunks
(:func:`check_rolls`, :class:`ForeignFileError`).  The manifest, the chunk
log, the lock and the repair of a folder are :mod:`dicetrace.scan.folder`'s.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

from dicetrace.scan.definition import ScanDefinition, as_written_now, describe_differences

#: The manifest beside ``rolls/`` (see :mod:`dicetrace.scan.folder`); the messages here name it.
MANIFEST = "_scan.parquet"
#: The key of a chunk file's own metadata (its chunk index and scan, as JSON).
METADATA_KEY = b"dicetrace"
#: The subfolder holding the rolls table: the chunk files, and nothing else.
ROLLS_DIR = "rolls"
_PART = re.compile(r"^part-(\d{6,})\.parquet$")


class ForeignFileError(FileExistsError):
    """The scan folder holds something that is none of the scan's own files (the message names it)."""


def part_name(c: int) -> str:
    return f"part-{c:06d}.parquet"


def rolls_dir(folder) -> Path:
    """The scan folder's Parquet dataset of rolls (``folder/rolls``): point any Parquet reader at it."""
    return Path(folder) / ROLLS_DIR


def file_sha256(path) -> tuple[str, int]:
    """(SHA-256 hex digest, size in bytes) of a file."""
    with open(path, "rb") as f:
        digest = hashlib.file_digest(f, "sha256")
        size = f.tell()
    return digest.hexdigest(), size


def _parts_in(folder: Path) -> dict[int, Path]:
    out = {}
    try:
        with os.scandir(folder) as it:
            for e in it:
                m = _PART.match(e.name)
                if m:
                    out[int(m.group(1))] = folder / e.name
    except (FileNotFoundError, NotADirectoryError):
        pass
    return out


def chunk_files(folder) -> dict[int, Path]:
    """Chunk index → path of every ``part-NNNNNN.parquet`` in ``folder/rolls`` (one listing, any number of chunks).

    A part left beside the manifest by an older dicetrace counts too, unless
    ``rolls/`` holds the same chunk.
    """
    folder = Path(folder)
    out = _parts_in(folder)
    out.update(_parts_in(folder / ROLLS_DIR))
    return dict(sorted(out.items()))


def move_legacy_parts(folder: Path) -> None:
    """Move the parts an older dicetrace wrote beside the manifest into ``rolls/`` (holding the lock)."""
    rolls = folder / ROLLS_DIR
    for c, p in _parts_in(folder).items():
        target = rolls / p.name
        if not target.exists():
            os.replace(p, target)


#: Files this process has hashed (or written), by path: (size, mtime_ns, sha256).  A file whose size and
#: modification time have not changed since is not hashed again (a scan's summary, map and recording
#: each read the folder); another process always hashes afresh.
_HASHED: dict[str, tuple[int, int, str]] = {}


def remember_digest(path: Path, digest: str) -> None:
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
            return f"its SHA-256 differs from the one recorded in {MANIFEST}"
        remember_digest(path, digest)
        return None
    try:
        n = pq.read_table(path).num_rows
    except Exception as e:  # noqa: BLE001 - any decoding error means "not a finished chunk"
        return f"it does not decode ({type(e).__name__}: {' '.join(str(e).split())[:120]})"
    return None if n == rows else f"it holds {n} rows, the chunk has {rows}"


def foreign_file(path: Path, folder: Path, why: str) -> ForeignFileError:
    return ForeignFileError(f"{str(path)!r} {why}: a scan folder holds only its own chunk files; move it out of "
                            f"{str(folder)!r} and re-run (its chunk is computed again), or use another folder")


def check_beside(folder, log: dict[int, dict]) -> None:
    """Refuse (:class:`ForeignFileError`, naming it) a chunk file beside the manifest of a folder in this layout.

    This dicetrace keeps every chunk in ``rolls/``; beside the manifest
    (``folder/part-NNNNNN.parquet``) only an older dicetrace's layout kept
    them.  Such a part is taken only where the chunk log names it there and
    ``rolls/`` does not hold its chunk (an older folder whose conversion was
    interrupted): anything else (a copy, a stray part) is refused, or every
    other Parquet reader would read its rows twice.
    """
    folder = Path(folder)
    for c, p in _parts_in(folder).items():
        entry = log.get(c)
        if entry is None or entry.get("file") != p.name or os.path.lexists(folder / ROLLS_DIR / p.name):
            raise foreign_file(p, folder, f"lies beside {MANIFEST}, where this scan keeps no chunk (they are in "
                               f"{ROLLS_DIR}/; Parquet readers of the folder would read its rows too)")


def check_rolls(folder, defn: ScanDefinition) -> None:
    """Refuse (:class:`ForeignFileError`, naming it) anything in ``rolls/`` that cannot be one of the scan's chunk files.

    That is another name than ``part-NNNNNN.parquet``, a chunk index beyond
    the scan, or something other than a regular file (a folder, a link).
    It only lists the folder: whether a chunk file is the scan's own is
    checked by :func:`prepare_folder`, holding the lock.
    """
    folder = Path(folder)
    rolls = folder / ROLLS_DIR
    if os.path.lexists(rolls) and not rolls.is_dir():
        raise FileExistsError(f"{str(rolls)!r} is not a folder: the scan's rolls table goes there; move it away")
    try:
        with os.scandir(rolls) as it:
            entries = sorted(it, key=lambda e: e.name)
    except FileNotFoundError:
        return
    for e in entries:
        p = rolls / e.name
        m = _PART.match(e.name)
        if not m or e.name != part_name(int(m.group(1))):
            raise foreign_file(p, folder, "is none of the scan's chunk files (rolls/ holds part-NNNNNN.parquet only)")
        c = int(m.group(1))
        if c >= defn.n_chunks:
            raise foreign_file(p, folder, f"is chunk {c:,}, beyond the scan's {defn.n_chunks:,} chunk(s)")
        if not e.is_file(follow_symlinks=False):
            kind = ("a folder" if e.is_dir(follow_symlinks=False) else "a link" if e.is_symlink()
                    else "not a regular file")
            raise foreign_file(p, folder, f"is {kind}, not a chunk file")


def chunk_identity(path: Path, defn: ScanDefinition, c: int, schema=None) -> str | None:
    """Why the chunk file ``path`` is not chunk ``c`` of the scan ``defn`` by what its footer says (None: it is).

    Its columns must be the scan's (``defn.schema``), and its dicetrace
    metadata (every chunk dicetrace writes carries it: the chunk index and
    the scan's definition) must name chunk ``c`` of this very definition,
    compared by value (:func:`~dicetrace.scan.definition.same_definition`).
    Only the footer is read (``schema``: the file's, where already read).  A
    file checked once by this process is not read again while its size and
    modification time hold.
    """
    key = (str(Path(path).absolute()), defn.digest(), c)
    try:
        st = os.stat(path)
        if schema is None and _IDENTIFIED.get(key) == (st.st_size, st.st_mtime_ns):
            return None
        if schema is None:
            schema = pq.read_schema(path)
    except Exception as e:  # noqa: BLE001 - any decoding error means "not a finished chunk"
        return f"it does not decode ({type(e).__name__}: {' '.join(str(e).split())[:120]})"
    why = _identity(schema, defn, c)
    if why is None:
        _IDENTIFIED[key] = (st.st_size, st.st_mtime_ns)
    return why


#: Chunk files this process found to be their chunk (:func:`chunk_identity`), by (path, definition, chunk):
#: (size, mtime_ns) when checked.
_IDENTIFIED: dict[tuple[str, str, int], tuple[int, int]] = {}


def _identity(schema, defn: ScanDefinition, c: int) -> str | None:
    return _columns_why(schema, defn) or _metadata_why(schema, defn, c)


def _columns_why(schema, defn: ScanDefinition) -> str | None:
    if not schema.equals(defn.schema, check_metadata=False):
        have, want = set(schema.names), set(defn.schema.names)
        if have == want:
            return "its columns' types are not a scan's"
        missing, extra = sorted(want - have), sorted(have - want)
        parts = ([f"{len(missing)} of the scan's columns missing ({', '.join(missing[:3])}"
                  f"{', ...' if len(missing) > 3 else ''})"] if missing else []) + \
                ([f"columns no scan has ({', '.join(extra[:3])}{', ...' if len(extra) > 3 else ''})"] if extra else [])
        return "its columns are not the scan's: " + "; ".join(parts)
    return None


def _metadata_why(schema, defn: ScanDefinition, c: int) -> str | None:
    raw = (schema.metadata or {}).get(METADATA_KEY)
    if raw is None:
        return "it carries no dicetrace metadata (every chunk dicetrace writes names its scan and chunk there)"
    try:
        meta = json.loads(raw)
    except ValueError:
        meta = None
    if not isinstance(meta, dict):
        return "its dicetrace metadata is unreadable"
    index = meta.get("chunk_index")
    if isinstance(index, bool) or not isinstance(index, int) or index != c:
        return f"its metadata says it is chunk {index!r}, not chunk {c}"
    if "scan" not in meta:
        return "its metadata names no scan definition"
    if json.dumps(as_written_now(meta["scan"]), sort_keys=True) == defn.canonical():  # as written: the same (fast)
        return None
    diffs = describe_differences(as_written_now(meta["scan"]), defn.to_dict())
    if diffs:
        return f"its metadata says it belongs to another scan ({'; '.join(diffs[:2])}{'; ...' if len(diffs) > 2 else ''})"
    return None


def verify_unlogged(path: Path, defn: ScanDefinition, c: int) -> str | None:
    """Why the chunk file ``path``, not in the chunk log, is not chunk ``c`` of the scan ``defn`` (None: it is).

    It must decode whole, hold chunk ``c``'s rows, carry the scan's columns
    and metadata (:func:`chunk_identity`: chunk ``c`` of this very
    definition), and its ``ic_id``s, grid indices and slice coordinates must
    be chunk ``c``'s, as the definition computes them: a copy of another
    chunk, another scan's chunk, or a file whose metadata was copied or
    stripped, is not adopted.
    """
    start, stop = defn.chunk_range(c)
    try:
        table = pq.read_table(path)
    except Exception as e:  # noqa: BLE001 - any decoding error means "not a finished chunk"
        return f"it does not decode ({type(e).__name__}: {' '.join(str(e).split())[:120]})"
    if table.num_rows != stop - start:
        return f"it holds {table.num_rows} rows, the chunk has {stop - start}"
    why = _columns_why(table.schema, defn)
    if why is not None:
        return why
    blk = defn.block(start, stop)

    def column(name):
        return table.column(name).to_numpy(zero_copy_only=False)

    if not np.array_equal(column("ic_id"), blk.ic_id):
        return f"its ic_ids are not chunk {c}'s ({start}..{stop - 1})"
    if not np.array_equal(np.stack([column(n) for n in "ijk"], axis=1), blk.index):
        return f"its grid indices are not chunk {c}'s"
    coords = np.stack([column(n).astype(np.float64) for n in "xyz"], axis=1)
    if not np.array_equal(coords, blk.coords, equal_nan=True):
        return f"its slice coordinates are not chunk {c}'s"
    if defn.posed:
        pose = np.stack([column(n) for n in ("qx", "qy", "qz", "qw", "z0_cm")], axis=1)
        if not np.array_equal(pose, np.c_[blk.orientations, blk.heights_cm]):
            return f"its poses (qx, qy, qz, qw, z0_cm) are not chunk {c}'s"
    return chunk_identity(path, defn, c, schema=table.schema)
