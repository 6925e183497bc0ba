"""Parquet sink: writes the ``rolls``, ``contacts`` and ``trajectory`` tables of :mod:`dicetrace.tables`.

Three Arrow tables with explicit schemas, readable with plain
``pandas.read_parquet`` (no dicetrace needed):

``rolls``
    one row per IC: ``ic_id``, slice coordinates ``x, y, z`` (null when the
    IC is not on a slice), the IC ``vx, vy, vz`` (cm/s) and ``Lx, Ly, Lz``
    (node-mass·cm²/s, in the preset's convention), ``preset``,
    ``integrator``, ``dt_s``, ``outcome`` (1..6; 0 undefined; -1 not
    settled), ``status``, ``steps``, ``t_settle_s``, ``contact_sets``
    (list<uint8>: bit k = node k+1 at or below the ground), its text form
    ``contact_sequence`` (the program's, e.g. ``0-6-68-8``) and
    ``n_contact_changes``.
``contacts``
    one row per node event: ``ic_id, step, t_s, node`` (1..8), ``kind``
    (``"enter"`` / ``"leave"``).
``trajectory``
    one row per step of one throw: ``ic_id, step, t_s``, centre of mass
    ``cm_{x,y,z}_cm``, its velocity ``vcm_{x,y,z}_cm_s``, the orientation
    quaternion ``qx, qy, qz, qw`` (world from body), ``Lx, Ly, Lz``, node
    positions ``n1_x_cm`` … ``n8_z_cm`` and energies ``e_stop_test,
    e_kin_trans, e_kin_rot, e_grav, e_elastic, e_total``
    (node-mass·cm²/s²).

Every table carries, under the schema-metadata key ``b"dicetrace"``, a JSON
object with the full configuration (``Config.as_dict()``), the IC(s) and the
dicetrace version: ``json.loads(pq.read_schema(f).metadata[b"dicetrace"])``.
Each field also states its unit in its own metadata (key ``b"unit"``).
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
