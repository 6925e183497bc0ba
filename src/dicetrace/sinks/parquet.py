"""Parquet sink: writes the ``rolls``, ``contacts`` and ``trajectory`` tables of :mod:`dicetrace.tables`.

The tables (columns, units, metadata) are defined in :mod:`dicetrace.tables`;
this module writes them atomically into a folder as ``rolls.parquet``,
``contacts.parquet`` and ``trajectory.parquet``, each one file that any
reader reads on its own (``pd.read_parquet("out/rolls.parquet")``,
``pl.read_parquet``, DuckDB's ``from 'out/rolls.parquet'``,
``pyarrow.parquet.read_table``; no dicetrace needed).

The folder is not one dataset: the three tables have different columns, and
a reader given the folder would stack their rows into one frame.  So a
plain-text note, ``README-tables.txt`` (:data:`NOTE_NAME`), is written
beside them: it says how to read each table and, being no Parquet file,
makes pandas, pyarrow.dataset and Polars refuse the folder, naming the note,
instead of mixing it; DuckDB refuses the mixed columns of its glob.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from dicetrace.simulate import Roll
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


#: The note written beside the tables (see the module docstring): a plain-text file, on purpose.
NOTE_NAME = "README-tables.txt"

NOTE_TEXT = """\
This folder holds Parquet tables written by dicetrace, one file per table:

  rolls.parquet       one row per initial condition: outcome, status, steps, contact sequence, ...
  contacts.parquet    one row per node entering or leaving the ground
  trajectory.parquet  one row per time step of one throw (when it was traced)

Read each file on its own, for example:

  pandas    pd.read_parquet("FOLDER/rolls.parquet")
  polars    pl.read_parquet("FOLDER/rolls.parquet")
  DuckDB    select * from 'FOLDER/rolls.parquet'
  pyarrow   pyarrow.parquet.read_table("FOLDER/rolls.parquet")

The folder itself is not one dataset: its tables have different columns, and a
reader given the folder would stack their rows into one frame. This note is not
a Parquet file, so pandas, pyarrow and Polars refuse the folder instead.
Every table carries the run's configuration as JSON under the schema metadata
key "dicetrace".
"""


# -- writing --------------------------------------------------------------------------------


def tables_for(source, *, coords=None, ic_ids=None, metadata: Mapping | None = None) -> dict[str, pa.Table]:
    """All tables a source supports: rolls and contacts always, trajectory for one traced Roll."""
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
    """Write ``rolls.parquet``, ``contacts.parquet`` (and ``trajectory.parquet``) into ``directory``, with the note.

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
        Table name → path written (the note, :data:`NOTE_NAME`, is not listed).
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
        note = destination(directory / NOTE_NAME, what="note")
        if note.kind != "file":
            raise OutputError(f"{note.label}: the note beside the tables is written as a regular file")
        tmp = st.path(note)
        try:
            tmp.write_text(NOTE_TEXT)
        except OSError as e:
            raise st.fail(note, e) from None
        if own:
            st.commit()
    except BaseException:
        if own:
            st.discard()
        raise
    return finals
