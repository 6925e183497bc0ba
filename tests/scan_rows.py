"""Comparing the rows of scans: a table or DataFrame reduced to its rows and columns."""

from __future__ import annotations

import pyarrow as pa


def rows(table) -> pa.Table:
    """Rows and columns only (no metadata, nullability flags or chunk layout), comparable with ``equals``."""
    df = table.to_pandas() if isinstance(table, pa.Table) else table
    return pa.Table.from_pandas(df.reset_index(drop=True), preserve_index=False).replace_schema_metadata(None)
