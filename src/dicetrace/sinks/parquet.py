"""Parquet sink: writes the ``rolls``, ``contacts`` and ``trajectory`` tables of :mod:`dicetrace.tables`.

The tables (columns, units, metadata) are defined in :mod:`dicetrace.tables`;
this module writes them atomically into a folder as ``rolls.parquet``,
``contacts.parquet`` and ``trajectory.parquet``, readable with plain
``pandas.read_parquet`` (no dicetrace needed).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from dicetrace.sinks._common import OutputError, Staging, destination, output_folder
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
    staging: Staging | None = None,
) -> dict[str, Path]:
    """Write ``rolls.parquet``, ``contacts.parquet`` (and ``trajectory.parquet``) into ``directory``.

    Give either a ``source`` (a Roll, Rolls or a BatchResult; see
    :func:`tables_for`) or ready ``tables`` (names from ``rolls``,
    ``contacts``, ``trajectory``).  Each file is written under a temporary
    name and renamed only once every file is complete: on error (a full
    disk raises :class:`~dicetrace.sinks._common.OutputError` naming the
    file) nothing is left behind, not even a folder made for them, and
    existing files are untouched.  With ``staging`` (a
    :class:`~dicetrace.sinks._common.Staging`) the files are only staged
    there, to be committed together with other outputs.

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
    directory = output_folder(directory, what="Parquet folder")
    own = staging is None
    st = Staging() if own else staging
    finals: dict[str, Path] = {}
    try:
        for name, table in tables.items():
            final = directory / f"{name}.parquet"
            dest = destination(final, what="Parquet file")
            if dest.kind != "file":
                raise OutputError(f"{dest.label}: Parquet tables are written as regular files")
            tmp = st.path(dest)
            try:
                with open(tmp, "wb") as f:  # closed on any error (a full disk), never left to the GC
                    pq.write_table(table, f, compression="zstd")
            except OSError as e:
                raise st.fail(dest, e) from None
            finals[name] = final
        if own:
            st.commit()
    except BaseException:
        if own:
            st.discard()
        raise
    return finals
