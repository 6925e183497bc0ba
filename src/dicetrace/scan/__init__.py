"""Scans of IC space: many throws, summaries only, streamed to a Parquet dataset.

>>> from dicetrace.ics import Grid
>>> from dicetrace.scan import scan, read_scan, label_grid
>>> report = scan(Grid("seed", "red-sea", 400), "scans/red-sea", progress=True)  # doctest: +SKIP
>>> outcome = label_grid("scans/red-sea")                                        # doctest: +SKIP

See :func:`scan` (run or resume; in memory, locally or on Dask),
:func:`iter_scan` (stream chunk tables), :func:`read_scan`,
:func:`label_grid`, :func:`grid_axes` and :func:`ic_at`; :class:`HandThrows` and
:class:`ThrowTable` (:mod:`dicetrace.scan.poses`) are spaces of hand throws, each from its own pose.  Without dicetrace,
point any Parquet reader at the folder as it is:
``polars.scan_parquet("scans/red-sea/")`` (its manifest ``_scan.parquet`` is
a Parquet file of the same columns and no rows).
"""

from dicetrace.scan.definition import DEFAULT_CHUNK, GPU_DEFAULT_CHUNK, ScanDefinition, config_from_dict
from dicetrace.scan.read import (
    MISSING,
    grid_axes,
    ic_at,
    label_grid,
    outcome_counts,
    read_scan,
    read_scan_table,
    scan_definition,
)
from dicetrace.scan.chunk_files import MANIFEST, ForeignFileError, rolls_dir
from dicetrace.scan.estimate import ScanEstimate, estimate_scan
from dicetrace.scan.folder import (
    CorruptChunkError,
    DeviceMismatchError,
    ScanBusyError,
    ScanMismatchError,
    ScanWarning,
    compute_chunk,
    has_manifest,
    prepare_folder,
    read_manifest,
    write_chunk,
)
from dicetrace.scan.poses import HandThrows, ThrowTable, read_throw_table
from dicetrace.scan.runner import ScanReport, iter_scan, scan
from dicetrace.tables import GRID_ROLLS_SCHEMA as ROLLS_SCHEMA

__all__ = [
    "CorruptChunkError",
    "DeviceMismatchError",
    "ForeignFileError",
    "HandThrows",
    "ThrowTable",
    "read_throw_table",
    "ScanBusyError",
    "ScanEstimate",
    "ScanWarning",
    "estimate_scan",
    "DEFAULT_CHUNK",
    "GPU_DEFAULT_CHUNK",
    "MANIFEST",
    "MISSING",
    "ROLLS_SCHEMA",
    "rolls_dir",
    "ScanDefinition",
    "ScanMismatchError",
    "ScanReport",
    "compute_chunk",
    "config_from_dict",
    "grid_axes",
    "has_manifest",
    "ic_at",
    "iter_scan",
    "label_grid",
    "outcome_counts",
    "prepare_folder",
    "read_manifest",
    "read_scan",
    "read_scan_table",
    "scan",
    "scan_definition",
    "write_chunk",
]
