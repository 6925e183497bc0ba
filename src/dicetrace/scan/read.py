"""Reading scans back: tables, labelled grids, and single ICs.

``read_scan(folder)`` gives the rolls table as a pandas DataFrame sorted by
``ic_id``; ``label_grid`` turns a grid scan into a numpy array indexed
``[i, j]`` or ``[i, j, k]`` (i along x), with ``grid_axes`` the coordinate
vector of each axis; ``ic_at`` finds a scanned IC by its slice coordinates
(to record it, reproduced exactly).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.dataset as pads
import pyarrow.parquet as pq

from dicetrace.ics import Grid
from dicetrace.scan.chunk_files import MANIFEST, METADATA_KEY, chunk_files, chunk_identity, verify_chunk
from dicetrace.scan.definition import ScanDefinition
from dicetrace.scan.folder import CorruptChunkError, has_chunk_log, read_chunk_log_checked, read_manifest

#: Fill value of label_grid cells that the (partial) scan has not computed yet.
MISSING = -2


def scan_definition(source) -> ScanDefinition:
    """The :class:`ScanDefinition` of a scan folder (or of a table/DataFrame read from one)."""
    if isinstance(source, (str, Path)):
        return ScanDefinition.from_dict(read_manifest(source)["definition"])
    meta = None
    if isinstance(source, pa.Table):
        meta = (source.schema.metadata or {}).get(METADATA_KEY)
    elif hasattr(source, "attrs"):
        meta = source.attrs.get("dicetrace")
    if meta is None:
        raise ValueError("no scan definition: pass the scan folder, or a table read by read_scan")
    d = json.loads(meta) if isinstance(meta, (bytes, str)) else meta
    return ScanDefinition.from_dict(d["scan"])


def _folder_of(folder) -> Path:
    if not isinstance(folder, (str, Path)) and not hasattr(folder, "__fspath__"):
        raise TypeError(f"folder must be a scan folder path, not {type(folder).__name__}")
    return Path(folder)


def verified_chunk_files(folder, manifest: dict | None = None) -> list[str]:
    """The chunk files the manifest of a scan folder lists, each checked against the checksum logged when it was
    written and against what its footer says it is (chunk c of this very scan: its columns, its metadata).

    Raises :class:`CorruptChunkError` naming the first file that does not
    match, or whose entry in the chunk log is broken.  Any other file in
    the folder (one the manifest does not list, a chunk not logged yet) is
    not read.  Only a folder of a dicetrace older still, without a chunk
    log, is read by name: its parts of this scan's chunk indices (the
    decoding names a damaged one).
    """
    folder = _folder_of(folder)
    manifest = read_manifest(folder) if manifest is None else manifest
    defn = ScanDefinition.from_dict(manifest["definition"])
    log, broken = read_chunk_log_checked(folder)
    listed = has_chunk_log(folder)
    files = []
    for c, p in chunk_files(folder).items():
        if c >= defn.n_chunks:
            continue
        if listed and c not in log:
            if str(c) in broken or "*" in broken:
                why = broken.get(str(c)) or broken["*"]
                raise CorruptChunkError(f"scan chunk {str(p)!r} cannot be trusted: the chunk log in {MANIFEST} is "
                                        f"broken ({why}); re-run the scan into {str(folder)!r} to check it again")
            continue
        entry = log.get(c)
        start, stop = defn.chunk_range(c)
        why = verify_chunk(p, entry, stop - start) if entry is not None else None
        if why is not None:
            raise CorruptChunkError(f"scan chunk {str(p)!r} is damaged: {why}; re-run the scan into {str(folder)!r} "
                                    "to recompute it")
        why = chunk_identity(p, defn, c)
        if why is not None:
            raise CorruptChunkError(f"scan chunk {str(p)!r} is not chunk {c} of the scan {MANIFEST} defines: {why}")
        files.append(str(p))
    return files


def _check_columns(columns, schema=None) -> None:
    """``columns`` (None: all) refused unless a list of names (of ``schema``, the scan's rows, where given)."""
    if columns is None:
        return
    if isinstance(columns, str) or not all(isinstance(c, str) for c in columns):
        raise TypeError(f"columns must be a list of column names, got {columns!r}")
    if schema is None:
        return
    unknown = [c for c in columns if c not in schema.names]
    if unknown:
        raise ValueError(f"unknown column(s) {', '.join(map(repr, unknown))} (this scan has {', '.join(schema.names)})")


def _dataset_table(files: list[str], columns, filter=None) -> pa.Table:
    """Read chunk files; a file that fails to decode is named in the error."""
    try:
        return pads.dataset(files, format="parquet").to_table(columns=columns, filter=filter)
    except (pa.ArrowException, OSError, ValueError):
        for f in files:  # find the culprit: a file that does not decode as a whole
            try:
                pq.read_table(f)
            except (pa.ArrowException, OSError, ValueError) as e:
                raise CorruptChunkError(
                    f"scan chunk {f!r} cannot be read ({type(e).__name__}: {' '.join(str(e).split())[:160]})"
                ) from None
        raise


def read_scan_table(folder, columns=None, filter=None) -> pa.Table:
    """The rolls table of a scan folder as Arrow, sorted by ``ic_id`` (finished chunks only).

    Every chunk is verified against the checksum in the manifest's chunk
    log first: a damaged one raises
    :class:`CorruptChunkError` naming the file.
    """
    folder = _folder_of(folder)
    _check_columns(columns)  # a bad argument before the folder is read
    manifest = read_manifest(folder)
    schema = ScanDefinition.from_dict(manifest["definition"]).schema
    _check_columns(columns, schema)
    files = verified_chunk_files(folder, manifest)
    cols = None if columns is None else list(dict.fromkeys(["ic_id", *columns]))
    if not files:
        table = schema.empty_table()
        if cols is not None:
            table = table.select(cols)
    else:
        table = _dataset_table(files, cols, filter).sort_by("ic_id")
    meta = {"scan": manifest["definition"], "dicetrace_version": manifest.get("dicetrace_version"),
            "die": ScanDefinition.from_dict(manifest["definition"]).die}
    return table.replace_schema_metadata({METADATA_KEY: json.dumps(meta, sort_keys=True).encode()})


def scan_row(folder, ic_id: int):
    """Row ``ic_id`` of a scan folder and the configuration that throws it again: ``(config, row)``, ``row`` a dict
    of its columns (None where the finished chunks hold no such row).

    ``simulate(ic, config=config, orientation=R)`` reproduces the row's
    outcome, steps and contact sequence, with ``ic`` its ``vx .. Lz`` (the
    preset's L convention) and, for a scan of throws from their own poses
    (the row has ``qx, qy, qz, qw, z0_cm``), ``R`` the rotation of its
    quaternion (``validate_orientations``) and ``config``'s ``z0_cm`` the
    row's own.
    """
    if isinstance(ic_id, bool) or not isinstance(ic_id, (int, np.integer)):
        raise TypeError(f"ic_id must be an integer, not {type(ic_id).__name__}")
    defn = scan_definition(folder)
    t = read_scan_table(folder, filter=pads.field("ic_id") == int(ic_id))
    if t.num_rows == 0:
        return defn.config, None
    return defn.config, {name: t.column(name)[0].as_py() for name in t.column_names}


def _column_counts(folder, column: str) -> dict:
    files = verified_chunk_files(_folder_of(folder))
    counts: dict = {}
    if not files:
        return counts
    try:
        batches = list(pads.dataset(files, format="parquet").to_batches(columns=[column]))
    except (pa.ArrowException, OSError, ValueError):
        _dataset_table(files, [column])  # names the file that fails
        raise
    for batch in batches:
        arr = batch.column(0)
        if pa.types.is_dictionary(arr.type):
            arr = arr.dictionary_decode()
        vals, n = np.unique(arr.to_numpy(zero_copy_only=False), return_counts=True)
        for v, c in zip(vals.tolist(), n.tolist()):
            counts[v] = counts.get(v, 0) + c
    return dict(sorted(counts.items()))


def outcome_counts(folder) -> dict[int, int]:
    """How many ICs of a scan folder ended on each outcome (streamed per chunk)."""
    return _column_counts(folder, "outcome")


def status_counts(folder) -> dict[str, int]:
    """How many ICs of a scan folder ended with each status (``settled``, ``time_cap``, ``blow_up``, ...)."""
    return _column_counts(folder, "status")


def read_scan(folder, columns=None):
    """The rolls table of a scan folder as a pandas DataFrame, sorted by ``ic_id``.

    ``df.attrs["dicetrace"]`` holds the scan definition (what
    :func:`label_grid` and :func:`grid_axes` use when given the frame).
    ``contact_sets`` come back as numpy uint8 arrays; group by the text
    ``contact_sequence`` instead.
    """
    t = read_scan_table(folder, columns=columns)
    df = t.to_pandas()
    df.attrs["dicetrace"] = json.loads(t.schema.metadata[METADATA_KEY])
    df.index = np.arange(len(df))
    return df


def _grid_of(source) -> Grid:
    defn = scan_definition(source)
    if not isinstance(defn.space, Grid):
        raise ValueError(f"the scan is a {defn.space.kind}, not a grid: it has no label grid")
    return defn.space


def grid_axes(source) -> list[np.ndarray]:
    """Coordinate vector of each grid axis (x, y[, z]), the program's point formula."""
    return _grid_of(source).axes()


def label_grid(source, column: str = "outcome", *, fill=MISSING) -> np.ndarray:
    """A grid scan's ``column`` as an array indexed ``[i, j]`` (2-D) or ``[i, j, k]`` (3-D).

    ``source`` is a scan folder, or a DataFrame/Arrow table read by
    :func:`read_scan` (or any frame with ``i, j, k`` and ``column`` plus the
    grid shape in ``attrs``).  ``outcome``: 1..6, 0 undefined, -1 did not
    settle; cells not computed yet hold ``fill`` (-2).  Other columns give
    arrays of their own dtype (object for strings, e.g. ``contact_sequence``).
    """
    grid = _grid_of(source)
    if isinstance(source, (str, Path)):
        t = read_scan_table(source, columns=["i", "j", "k", column])
        i, j, k = (t.column(n).to_numpy() for n in ("i", "j", "k"))
        vals = t.column(column).to_numpy(zero_copy_only=False)
    elif isinstance(source, pa.Table):
        i, j, k = (source.column(n).to_numpy() for n in ("i", "j", "k"))
        vals = source.column(column).to_numpy(zero_copy_only=False)
    else:
        i, j, k = (np.asarray(source[n]) for n in ("i", "j", "k"))
        vals = np.asarray(source[column])
    shape3 = tuple(grid.shape) + (1,) * (3 - grid.ndim)
    if vals.dtype.kind in "iub":
        out = np.full(shape3, fill, dtype=np.result_type(vals.dtype, np.int8))
    elif vals.dtype.kind == "f":
        out = np.full(shape3, np.nan, dtype=vals.dtype)
    else:
        out = np.full(shape3, None, dtype=object)
    out[i, j, k] = vals
    return out.reshape(grid.shape)


def ic_at(folder, coords, *, tol: float | None = None):
    """The scanned IC nearest to slice coordinates ``coords`` (x, y[, z]).

    Returns ``(ic, config, row)``: the IC exactly as stored (6 floats, the
    preset's L convention), the scan's :class:`~dicetrace.params.Config`,
    and the row as a dict.  ``simulate(ic, config=config)`` reproduces the
    row's outcome, steps and contact sequence.  ``tol`` (slice units):
    refuse a nearest point farther than that (default: half a grid cell on
    grids, no limit otherwise).
    """
    defn = scan_definition(folder)
    try:
        c = np.asarray(coords, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise ValueError(f"coords must be numbers (x, y[, z]), got {coords!r}") from None
    if not np.all(np.isfinite(c)):
        raise ValueError("coords must be finite numbers")
    nd = defn.space.ndim
    if defn.posed:
        raise ValueError(f"the scan's throws ({defn.space.kind}) start from their own poses and lie on no slice: "
                         "pick a row by its ic_id (dicetrace record --rolls FOLDER --ic-id N)")
    if c.size != nd:
        raise ValueError(f"the scan's slice is {nd}-D: give {nd} coordinates, got {c.size}")
    cols = ["x", "y", "z"][:nd]
    t = read_scan_table(folder)
    if t.num_rows == 0:
        raise ValueError(f"{str(folder)!r} holds no finished chunk yet")
    pts = np.stack([t.column(n).to_numpy(zero_copy_only=False) for n in cols], axis=1)
    d = np.sqrt(((pts - c) ** 2).sum(axis=1))
    r = int(np.argmin(d))
    if tol is None and isinstance(defn.space, Grid):
        steps = [(hi - lo) / max(n - 1, 1) for (lo, hi), n in zip(defn.space.window, defn.space.res)]
        tol = 0.5 * float(np.sqrt(sum(s * s for s in steps))) + 1e-12
    if tol is not None and d[r] > tol:
        at = ", ".join(f"{float(v):g}" for v in c)
        raise ValueError(f"no scanned IC near ({at}) (nearest at distance {float(d[r]):.3g} > {float(tol):.3g})")
    row = {name: t.column(name)[r].as_py() for name in t.column_names}
    ic = np.array([row[n] for n in ("vx", "vy", "vz", "Lx", "Ly", "Lz")], dtype=np.float64)
    return ic, defn.config, row
