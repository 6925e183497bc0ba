"""Parquet sink: writes the ``rolls``, ``contacts`` and ``trajectory`` tables of :mod:`dicetrace.tables`.

The tables (columns, units, metadata) are defined in :mod:`dicetrace.tables`;
this module writes them atomically into a folder as ``rolls.parquet``,
``contacts.parquet`` and ``trajectory.parquet``, readable with plain
``pandas.read_parquet`` (no dicetrace needed).
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from dicetrace.sinks._common import remove_quietly, temp_path_beside
from dicetrace.tables import (  # noqa: F401  (re-exported: the sink's public names)
    CONTACTS_SCHEMA,
    GRID_ROLLS_SCHEMA,
    METADATA_KEY,
    ROLLS_SCHEMA,
    TABLE_NAMES,
    TRAJECTORY_SCHEMA,
    _ids,
    contacts_table,
    metadata_json,
    read_metadata,
    rolls_table,
    trajectory_table,
)


# -- writing --------------------------------------------------------------------------------


def tables_for(source, *, coords=None, ic_ids=None, metadata: Mapping | None = None) -> dict[str, pa.Table]:
    """All tables a source supports: rolls and contacts always, trajectory for one traced Roll."""
    from dicetrace.simulate import Roll

    out = {
        "rolls": rolls_table(source, coords=coords, ic_ids=ic_ids, metadata=metadata),
        "contacts": contacts_table(source, ic_ids=ic_ids, metadata=metadata),
    }
    if isinstance(source, Roll) and source.trace is not None and source.trace.node_offsets is not None:
        if source.trace.energy is not None:
            ic_id = int(_ids(ic_ids, 1)[0])
            out["trajectory"] = trajectory_table(source, ic_id=ic_id, metadata=metadata)
    return out


def write_tables(
    directory,
    source=None,
    *,
    tables: Mapping[str, pa.Table] | None = None,
    coords=None,
    ic_ids=None,
    metadata: Mapping | None = None,
) -> dict[str, Path]:
    """Write ``rolls.parquet``, ``contacts.parquet`` (and ``trajectory.parquet``) into ``directory``.

    Give either a ``source`` (a Roll, Rolls or a BatchResult; see
    :func:`tables_for`) or ready ``tables`` (names from ``rolls``,
    ``contacts``, ``trajectory``).  Each file is written under a temporary
    name and renamed only once every file is complete: on error nothing is
    left behind and existing files are untouched.

    Returns
    -------
    dict
        Table name → path written.
    """
    if (source is None) == (tables is None):
        raise ValueError("give either a source or tables")
    if tables is None:
        tables = tables_for(source, coords=coords, ic_ids=ic_ids, metadata=metadata)
    unknown = set(tables) - set(TABLE_NAMES)
    if unknown:
        raise ValueError(f"unknown table name(s) {sorted(unknown)}; expected {TABLE_NAMES}")
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    staged: list[tuple[Path, Path]] = []
    try:
        for name, table in tables.items():
            final = directory / f"{name}.parquet"
            tmp = temp_path_beside(final)
            staged.append((tmp, final))
            pq.write_table(table, tmp, compression="zstd")
        for tmp, final in staged:
            os.replace(tmp, final)
    finally:
        for tmp, _ in staged:
            remove_quietly(tmp)
    return {final.stem: final for _, final in staged}
