"""Parquet sink: the ``rolls``, ``contacts`` and ``trajectory`` tables (DESIGN.md section 6).

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

from dicetrace.sinks._common import quaternions_xyzw, remove_quietly, temp_path_beside, written_rows

METADATA_KEY = b"dicetrace"
TABLE_NAMES = ("rolls", "contacts", "trajectory")
#: ICs listed in the metadata up to this many (beyond it only their count: they are in the rows).
MAX_METADATA_ICS = 1000

_STATUS_NAMES = ("settled", "time_cap", "non_finite", "blow_up")
_ENERGY_COLUMNS = (
    ("stop_test", "e_stop_test"),
    ("kinetic_translational", "e_kin_trans"),
    ("kinetic_rotational", "e_kin_rot"),
    ("gravitational", "e_grav"),
    ("elastic", "e_elastic"),
    ("total", "e_total"),
)
_ENERGY_UNIT = "node-mass*cm^2/s^2"
_L_UNIT = "node-mass*cm^2/s"


def _f(name: str, typ: pa.DataType, unit: str | None = None, nullable: bool = False) -> pa.Field:
    return pa.field(name, typ, nullable=nullable, metadata={b"unit": unit.encode()} if unit else None)


ROLLS_SCHEMA = pa.schema(
    [
        _f("ic_id", pa.int64()),
        _f("x", pa.float64(), "slice coordinate", nullable=True),
        _f("y", pa.float64(), "slice coordinate", nullable=True),
        _f("z", pa.float64(), "slice coordinate", nullable=True),
        _f("vx", pa.float64(), "cm/s"),
        _f("vy", pa.float64(), "cm/s"),
        _f("vz", pa.float64(), "cm/s"),
        _f("Lx", pa.float64(), _L_UNIT),
        _f("Ly", pa.float64(), _L_UNIT),
        _f("Lz", pa.float64(), _L_UNIT),
        _f("preset", pa.string()),
        _f("integrator", pa.string()),
        _f("dt_s", pa.float64(), "s"),
        _f("outcome", pa.int8()),
        _f("status", pa.string()),
        _f("steps", pa.int64()),
        _f("t_settle_s", pa.float64(), "s"),
        _f("contact_sets", pa.list_(pa.uint8())),
        _f("contact_sequence", pa.string()),
        _f("n_contact_changes", pa.int32()),
    ]
)

CONTACTS_SCHEMA = pa.schema(
    [
        _f("ic_id", pa.int64()),
        _f("step", pa.int64()),
        _f("t_s", pa.float64(), "s"),
        _f("node", pa.int8()),
        _f("kind", pa.string()),
    ]
)


def _trajectory_fields() -> list[pa.Field]:
    fields = [_f("ic_id", pa.int64()), _f("step", pa.int64()), _f("t_s", pa.float64(), "s")]
    fields += [_f(f"cm_{a}_cm", pa.float64(), "cm") for a in "xyz"]
    fields += [_f(f"vcm_{a}_cm_s", pa.float64(), "cm/s") for a in "xyz"]
    fields += [_f(f"q{a}", pa.float64()) for a in "xyzw"]
    fields += [_f(f"L{a}", pa.float64(), _L_UNIT) for a in "xyz"]
    fields += [_f(f"n{k}_{a}_cm", pa.float64(), "cm") for k in range(1, 9) for a in "xyz"]
    fields += [_f(col, pa.float64(), _ENERGY_UNIT) for _, col in _ENERGY_COLUMNS]
    return fields


TRAJECTORY_SCHEMA = pa.schema(_trajectory_fields())

# "0", "1", ..., "12345678": the program's text of every 8-bit contact set
_SET_TEXT = np.array(["".join(str(k + 1) for k in range(8) if m >> k & 1) or "0" for m in range(256)], dtype=object)


# -- metadata ----------------------------------------------------------------------------


def metadata_json(config, ics, *, extra: Mapping | None = None) -> dict:
    """The metadata object stored under ``b"dicetrace"`` in every table's schema."""
    import dicetrace

    ics = np.asarray(ics, dtype=np.float64).reshape(-1, 6)
    meta = {
        "dicetrace_version": dicetrace.__version__,
        "config": config.as_dict(),
        "ic_fields": ["vx", "vy", "vz", "Lx", "Ly", "Lz"],
        "ic_units": ["cm/s"] * 3 + [_L_UNIT] * 3,
        "l_convention": config.preset.l_convention,
        "n_ics": int(len(ics)),
    }
    if len(ics) <= MAX_METADATA_ICS:
        meta["ics"] = ics.tolist()
    if extra:
        meta.update(dict(extra))
    return meta


def _with_metadata(table: pa.Table, meta: dict) -> pa.Table:
    md = dict(table.schema.metadata or {})
    md[METADATA_KEY] = json.dumps(meta, sort_keys=True, allow_nan=True).encode()
    return table.replace_schema_metadata(md)


def read_metadata(path) -> dict:
    """The ``b"dicetrace"`` metadata of a Parquet file written by this module."""
    md = pq.read_schema(path).metadata or {}
    if METADATA_KEY not in md:
        raise ValueError(f"{path}: no dicetrace metadata")
    return json.loads(md[METADATA_KEY])


# -- normalising the sources --------------------------------------------------------------


class _Summaries:
    """Summary arrays of m throws, from a BatchResult or from Rolls."""

    def __init__(self, source):
        from dicetrace.simulate import BatchResult, Roll

        if isinstance(source, BatchResult):
            self.config = source.config
            self.ics = np.asarray(source.ics, dtype=np.float64).reshape(-1, 6)
            self.outcome = np.asarray(source.outcome, dtype=np.int8)
            self.status_code = np.asarray(source.status_code, dtype=np.int64)
            self.steps = np.asarray(source.steps, dtype=np.int64)
            self.t_settle_s = np.asarray(source.t_settle_s, dtype=np.float64)
            self.set_offsets = np.asarray(source.set_offsets, dtype=np.int64)
            self.sets = np.asarray(source.sets, dtype=np.uint8)
            self.set_steps = np.asarray(source.set_steps, dtype=np.int64)
            return
        rolls = [source] if isinstance(source, Roll) else list(source)
        if not rolls:
            raise ValueError("no rolls to tabulate")
        for r in rolls:
            if not isinstance(r, Roll):
                raise TypeError(f"expected Roll objects, got {type(r).__name__}")
        self.config = rolls[0].config
        for r in rolls[1:]:
            if r.config != self.config:
                raise ValueError("rolls with different configurations cannot share one table (metadata holds one config)")
        codes = {name: i for i, name in enumerate(_STATUS_NAMES)}
        self.ics = np.array([r.ic for r in rolls], dtype=np.float64).reshape(-1, 6)
        self.outcome = np.array([r.outcome for r in rolls], dtype=np.int8)
        self.status_code = np.array([codes[r.status] for r in rolls], dtype=np.int64)
        self.steps = np.array([r.steps for r in rolls], dtype=np.int64)
        self.t_settle_s = np.array([r.t_settle_s for r in rolls], dtype=np.float64)
        counts = np.array([len(r.contact_sets) for r in rolls], dtype=np.int64)
        self.set_offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        self.sets = np.concatenate([np.asarray(r.contact_sets, dtype=np.uint8) for r in rolls])
        self.set_steps = np.concatenate([np.asarray(r.contact_steps, dtype=np.int64) for r in rolls])

    def __len__(self) -> int:
        return len(self.outcome)

    def sequences(self) -> list[str]:
        """The program's text form of every IC's contact-set sequence."""
        texts = _SET_TEXT[self.sets]
        off = self.set_offsets
        return ["-".join(texts[off[i] : off[i + 1]]) for i in range(len(self))]

    def events(self):
        """Per-node contact events of all ICs: (row, step, node 1..8, entered), by row, step, node."""
        m = len(self)
        counts = np.diff(self.set_offsets)
        owner = np.repeat(np.arange(m), counts)
        sets = self.sets.astype(np.int64)
        prev = np.empty_like(sets)
        if len(sets):
            prev[1:] = sets[:-1]
            prev[self.set_offsets[:-1][counts > 0]] = 0  # each IC starts from the empty set
        changed = prev ^ sets
        bits = (changed[:, None] >> np.arange(8)) & 1  # (nsets, 8)
        i_set, k = np.nonzero(bits)  # row-major: by set (hence IC and step), then node
        entered = ((sets[i_set] >> k) & 1).astype(bool)
        return owner[i_set], self.set_steps[i_set], (k + 1).astype(np.int8), entered


def _ids(ic_ids, m: int) -> np.ndarray:
    if ic_ids is None:
        return np.arange(m, dtype=np.int64)
    a = np.asarray(ic_ids, dtype=np.int64).reshape(-1)
    if len(a) != m:
        raise ValueError(f"ic_ids has {len(a)} entries for {m} ICs")
    return a


def _coords(coords, m: int) -> dict[str, pa.Array]:
    out = {}
    if coords is None:
        cols = {}
    elif isinstance(coords, Mapping):
        unknown = set(coords) - {"x", "y", "z"}
        if unknown:
            raise ValueError(f"coords may only name x, y, z; got {sorted(unknown)}")
        cols = {k: np.asarray(v, dtype=np.float64).reshape(-1) for k, v in coords.items() if v is not None}
    else:
        a = np.asarray(coords, dtype=np.float64)
        if a.ndim == 1:
            a = a.reshape(1, -1)
        if a.ndim != 2 or a.shape[1] not in (1, 2, 3):
            raise ValueError(f"coords must be (m, 2) or (m, 3) (x, y[, z]), got shape {a.shape}")
        cols = {name: a[:, j] for j, name in enumerate("xyz"[: a.shape[1]])}
    for name in "xyz":
        if name in cols:
            if len(cols[name]) != m:
                raise ValueError(f"coords {name!r} has {len(cols[name])} entries for {m} ICs")
            out[name] = pa.array(cols[name], type=pa.float64())
        else:
            out[name] = pa.nulls(m, type=pa.float64())
    return out


# -- tables ---------------------------------------------------------------------------------


def rolls_table(source, *, coords=None, ic_ids=None, metadata: Mapping | None = None) -> pa.Table:
    """The ``rolls`` table: one row per IC.

    Parameters
    ----------
    source
        A :class:`~dicetrace.simulate.BatchResult`, a
        :class:`~dicetrace.simulate.Roll` or a sequence of Rolls (one config).
    coords
        Slice coordinates of the ICs: an (m, 2) or (m, 3) array (x, y[, z])
        or a mapping ``{"x": ..., "y": ..., "z": ...}``; missing ones are null.
    ic_ids
        Integer id of each IC (default 0..m-1).
    metadata
        Extra entries for the ``b"dicetrace"`` metadata object (e.g. the
        slice's name).
    """
    s = _Summaries(source)
    m = len(s)
    cfg = s.config
    c = _coords(coords, m)
    sets_arr = pa.ListArray.from_arrays(
        pa.array(s.set_offsets.astype(np.int32), type=pa.int32()), pa.array(s.sets, type=pa.uint8())
    ).cast(pa.list_(pa.uint8()))
    status = np.array(_STATUS_NAMES, dtype=object)[s.status_code]
    cols = {
        "ic_id": pa.array(_ids(ic_ids, m), type=pa.int64()),
        **c,
        **{name: pa.array(s.ics[:, j], type=pa.float64()) for j, name in enumerate(("vx", "vy", "vz", "Lx", "Ly", "Lz"))},
        "preset": pa.array([cfg.preset.name] * m, type=pa.string()),
        "integrator": pa.array([cfg.numerics.integrator] * m, type=pa.string()),
        "dt_s": pa.array(np.full(m, cfg.numerics.dt_s), type=pa.float64()),
        "outcome": pa.array(s.outcome, type=pa.int8()),
        "status": pa.array(status.tolist(), type=pa.string()),
        "steps": pa.array(s.steps, type=pa.int64()),
        "t_settle_s": pa.array(s.t_settle_s, type=pa.float64()),
        "contact_sets": sets_arr,
        "contact_sequence": pa.array(s.sequences(), type=pa.string()),
        "n_contact_changes": pa.array(np.diff(s.set_offsets) - 1, type=pa.int32()),
    }
    table = pa.Table.from_arrays([cols[f.name] for f in ROLLS_SCHEMA], schema=ROLLS_SCHEMA)
    return _with_metadata(table, metadata_json(cfg, s.ics, extra=metadata))


def contacts_table(source, *, ic_ids=None, metadata: Mapping | None = None) -> pa.Table:
    """The ``contacts`` table: one row per node entering or leaving contact (z ≤ 0).

    ``source`` as for :func:`rolls_table`; events are ordered by IC, step, node.
    """
    s = _Summaries(source)
    ids = _ids(ic_ids, len(s))
    row, step, node, entered = s.events()
    cols = [
        pa.array(ids[row], type=pa.int64()),
        pa.array(step, type=pa.int64()),
        pa.array(step * s.config.numerics.dt_s, type=pa.float64()),
        pa.array(node, type=pa.int8()),
        pa.array(np.where(entered, "enter", "leave").tolist(), type=pa.string()),
    ]
    table = pa.Table.from_arrays(cols, schema=CONTACTS_SCHEMA)
    return _with_metadata(table, metadata_json(s.config, s.ics, extra=metadata))


def trajectory_table(roll, *, ic_id: int = 0, metadata: Mapping | None = None) -> pa.Table:
    """The ``trajectory`` table of one throw: one row per step (row 0 the IC).

    ``roll`` must carry states and energy:
    ``simulate(ic, record=Record(states=True, energy=True))``.
    """
    tr = roll.trace
    if tr is None or tr.node_offsets is None or tr.energy is None:
        raise ValueError(
            "trajectory_table needs a roll with states and energy: simulate(..., record=Record(states=True, energy=True))"
        )
    rows = written_rows(tr)  # a failed run may leave its last row unwritten
    n = int(rows.sum())
    cols: dict[str, np.ndarray] = {
        "ic_id": np.full(n, int(ic_id), dtype=np.int64),
        "step": tr.step[rows].astype(np.int64),
        "t_s": tr.t_s[rows].astype(np.float64),
    }
    for j, a in enumerate("xyz"):
        cols[f"cm_{a}_cm"] = tr.cm_pos[rows, j]
        cols[f"vcm_{a}_cm_s"] = tr.cm_vel[rows, j]
    q = quaternions_xyzw(tr)[rows]
    for j, a in enumerate("xyzw"):
        cols[f"q{a}"] = q[:, j]
    for j, a in enumerate("xyz"):
        cols[f"L{a}"] = tr.L[rows, j]
    nodes = tr.node_pos[rows]
    for k in range(8):
        for j, a in enumerate("xyz"):
            cols[f"n{k + 1}_{a}_cm"] = nodes[:, k, j]
    for key, col in _ENERGY_COLUMNS:
        cols[col] = np.asarray(tr.energy[key])[rows]
    arrays = [pa.array(np.ascontiguousarray(cols[f.name]), type=f.type) for f in TRAJECTORY_SCHEMA]
    table = pa.Table.from_arrays(arrays, schema=TRAJECTORY_SCHEMA)
    return _with_metadata(table, metadata_json(roll.config, roll.ic, extra=metadata))


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
