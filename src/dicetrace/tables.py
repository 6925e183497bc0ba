"""The Arrow tables of throws: ``rolls``, ``contacts`` and ``trajectory`` (one schema each).

The one builder of each table: the Parquet sink writes them, scans store
``rolls`` rows, and ``BatchResult.to_arrow()`` returns them.

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
    ``n_contact_changes``; with exact contact events
    (``simulate(..., record=Record(..., events=True))``, docs/model.md §8.1) also
    ``contact_times_s`` (list<float64>: the time each set began).
``contacts``
    one row per node event: ``ic_id, step, t_s, node`` (1..8), ``kind``
    (``"enter"`` / ``"leave"``); ``t_s`` is the end of the step at which the
    change was seen, or with exact contact events the event's own time.
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
from collections.abc import Mapping

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

import dicetrace
from dicetrace.core._jit import jit
from dicetrace.status import LABELS

METADATA_KEY = b"dicetrace"
TABLE_NAMES = ("rolls", "contacts", "trajectory")
#: ICs listed in the metadata up to this many (beyond it only their count: they are in the rows).
MAX_METADATA_ICS = 1000

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


#: Grid indices of a scan's ICs (k = 0 on 2-D grids, -1 for ICs not on a grid).
GRID_FIELDS = [_f(name, pa.int32()) for name in ("i", "j", "k")]

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

#: The column a ``rolls`` table of exact contact events adds at its end: when each contact set began.
EVENT_TIMES_FIELD = _f("contact_times_s", pa.list_(pa.float64()), "s")
#: The columns a ``rolls`` table of throws from their own poses (``simulate_batch(orientations=, heights_cm=)``)
#: adds at its end: the starting orientation, a unit quaternion x, y, z, w (world from body), and the start
#: height of the centre of mass.
POSE_FIELDS = [*(_f(name, pa.float64(), "quaternion, world from body") for name in ("qx", "qy", "qz", "qw")),
               _f("z0_cm", pa.float64(), "cm")]

#: ``ROLLS_SCHEMA`` with the grid indices after ``ic_id``: the rows of a scan dataset.
GRID_ROLLS_SCHEMA = pa.schema([ROLLS_SCHEMA.field(0), *GRID_FIELDS, *list(ROLLS_SCHEMA)[1:]])
#: ``GRID_ROLLS_SCHEMA`` with ``contact_times_s``: the rows of a scan with exact contact events.
GRID_ROLLS_EVENTS_SCHEMA = GRID_ROLLS_SCHEMA.append(EVENT_TIMES_FIELD)

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

# Text of every 8-bit contact set: node numbers ascending, "0" for the empty set.
_SET_TEXT = ["".join(str(k + 1) for k in range(8) if m >> k & 1) or "0" for m in range(256)]
SET_TEXT_LEN = np.array([len(t) for t in _SET_TEXT], dtype=np.int64)
SET_TEXT_BYTES = np.zeros((256, 8), dtype=np.uint8)
for _m, _t in enumerate(_SET_TEXT):
    SET_TEXT_BYTES[_m, : len(_t)] = np.frombuffer(_t.encode(), dtype=np.uint8)


@jit
def _sequence_lengths(sets, offsets, lens_out):
    m = offsets.shape[0] - 1
    total = 0
    for i in range(m):
        n = 0
        for s in range(offsets[i], offsets[i + 1]):
            n += SET_TEXT_LEN[sets[s]] + 1
        if n > 0:
            n -= 1
        lens_out[i] = n
        total += n
    return total


@jit
def _sequence_bytes(sets, offsets, str_offsets, out):
    m = offsets.shape[0] - 1
    pos = 0
    str_offsets[0] = 0
    for i in range(m):
        for s in range(offsets[i], offsets[i + 1]):
            if s > offsets[i]:
                out[pos] = 45  # "-"
                pos += 1
            c = sets[s]
            for q in range(SET_TEXT_LEN[c]):
                out[pos] = SET_TEXT_BYTES[c, q]
                pos += 1
        str_offsets[i + 1] = pos


def sequences_array(sets: np.ndarray, offsets: np.ndarray) -> pa.StringArray:
    """The program's text form of each IC's contact-set sequence, as an Arrow string array."""
    sets = np.ascontiguousarray(sets, dtype=np.uint8)
    offsets = np.ascontiguousarray(offsets, dtype=np.int64)
    m = len(offsets) - 1
    lens = np.empty(m, dtype=np.int64)
    total = _sequence_lengths(sets, offsets, lens)
    if total >= 2**31:
        raise ValueError("contact sequences too long for one Arrow string array; use a smaller chunk")
    data = np.empty(total, dtype=np.uint8)
    str_off = np.empty(m + 1, dtype=np.int64)
    _sequence_bytes(sets, offsets, str_off, data)
    return pa.StringArray.from_buffers(m, pa.py_buffer(str_off.astype(np.int32)), pa.py_buffer(data))


# -- metadata ----------------------------------------------------------------------------


def metadata_json(config, ics, *, extra: Mapping | None = None) -> dict:
    """The metadata object stored under ``b"dicetrace"`` in every table's schema."""
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


def _is_batch(source) -> bool:
    """Whether ``source`` is a :class:`~dicetrace.simulate.BatchResult` (by what it holds: tables are built
    from the results simulate returns and never import simulate, which builds its tables from here)."""
    return all(hasattr(source, a) for a in ("set_offsets", "status_code", "t_settle_s", "coords", "config"))


def _is_roll(source) -> bool:
    """Whether ``source`` is a :class:`~dicetrace.simulate.Roll` (by what it holds, as :func:`_is_batch`)."""
    return all(hasattr(source, a) for a in ("ic", "contact_sets", "contact_steps", "status", "config"))


class _Summaries:
    """Summary arrays of m throws, from a BatchResult or from Rolls."""

    def __init__(self, source):
        if _is_batch(source):
            self.config = source.config
            self.ics = np.asarray(source.ics, dtype=np.float64).reshape(-1, 6)
            self.outcome = np.asarray(source.outcome, dtype=np.int8)
            self.status_code = np.asarray(source.status_code, dtype=np.int64)
            self.steps = np.asarray(source.steps, dtype=np.int64)
            self.t_settle_s = np.asarray(source.t_settle_s, dtype=np.float64)
            self.set_offsets = np.asarray(source.set_offsets, dtype=np.int64)
            self.sets = np.asarray(source.sets, dtype=np.uint8)
            self.set_steps = np.asarray(source.set_steps, dtype=np.int64)
            times = getattr(source, "set_times", None)
            self.set_times = None if times is None else np.asarray(times, dtype=np.float64)
            self.coords = source.coords
            self.orientations = getattr(source, "orientations", None)
            self.heights_cm = getattr(source, "heights_cm", None)
            return
        rolls = [source] if _is_roll(source) else list(source)
        if not rolls:
            raise ValueError("no rolls to tabulate")
        for r in rolls:
            if not _is_roll(r):
                raise TypeError(f"expected Roll objects, got {type(r).__name__}")
        self.config = rolls[0].config
        for r in rolls[1:]:
            if r.config != self.config:
                raise ValueError("rolls with different configurations cannot share one table (metadata holds one config)")
        self.ics = np.array([r.ic for r in rolls], dtype=np.float64).reshape(-1, 6)
        self.outcome = np.array([r.outcome for r in rolls], dtype=np.int8)
        self.status_code = np.array([int(r.status) for r in rolls], dtype=np.int64)
        self.steps = np.array([r.steps for r in rolls], dtype=np.int64)
        self.t_settle_s = np.array([r.t_settle_s for r in rolls], dtype=np.float64)
        counts = np.array([len(r.contact_sets) for r in rolls], dtype=np.int64)
        self.set_offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        self.sets = np.concatenate([np.asarray(r.contact_sets, dtype=np.uint8) for r in rolls])
        self.set_steps = np.concatenate([np.asarray(r.contact_steps, dtype=np.int64) for r in rolls])
        with_times = [r.contact_times is not None for r in rolls]
        if any(with_times) and not all(with_times):
            raise ValueError("rolls with and without exact contact events cannot share one table")
        self.set_times = np.concatenate([r.contact_times for r in rolls]) if all(with_times) else None
        self.orientations = self.heights_cm = None
        self.coords = None

    def __len__(self) -> int:
        return len(self.outcome)

    def events(self):
        """Per-node contact events of all ICs: (row, step, t_s, node 1..8, entered), by row, step, node.

        ``t_s``: the end of the step at which the change was seen (step·dt), or the event's exact time.
        """
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
        step = self.set_steps[i_set]
        t_s = step * self.config.numerics.dt_s if self.set_times is None else self.set_times[i_set]
        return owner[i_set], step, t_s, (k + 1).astype(np.int8), entered


def node_events(source):
    """Per-node contact events of a Roll, Rolls or a BatchResult: (row, step, t_s, node 1..8, entered), by row,
    step, node; ``t_s`` the end of the step at which the change was seen, or the event's exact time where the
    throws recorded exact contact events.  What the ``contacts`` table, the Rerun sink's contact log and
    ``Roll.contact_events`` hold."""
    return _Summaries(source).events()


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
            nan = np.isnan(cols[name])
            out[name] = pa.array(cols[name], type=pa.float64(), mask=nan if nan.any() else None)
        else:
            out[name] = pa.nulls(m, type=pa.float64())
    return out


# -- tables ---------------------------------------------------------------------------------


def _const_str(v: str, m: int) -> pa.Array:
    return pa.DictionaryArray.from_arrays(pa.array(np.zeros(m, np.int8)), pa.array([v])).cast(pa.string())


def rolls_table(source, *, coords=None, ic_ids=None, index=None, metadata: Mapping | None = None) -> pa.Table:
    """The ``rolls`` table: one row per IC (the one builder of it; built column-wise).

    Parameters
    ----------
    source
        A :class:`~dicetrace.simulate.BatchResult`, a
        :class:`~dicetrace.simulate.Roll` or a sequence of Rolls (one config).
    coords
        Slice coordinates of the ICs: an (m, 2) or (m, 3) array (x, y[, z])
        or a mapping ``{"x": ..., "y": ..., "z": ...}``; missing ones and NaN
        are null.  Default: a BatchResult's own ``coords`` (ICs that came
        with them, e.g. from :func:`~dicetrace.ics.seed_slice`), else null.
    ic_ids
        Integer id of each IC (default 0..m-1).
    index
        Grid indices (m, 3) int: adds the columns ``i, j, k`` after ``ic_id``
        (``GRID_ROLLS_SCHEMA``, a scan dataset's rows).
    metadata
        Extra entries for the ``b"dicetrace"`` metadata object (e.g. the
        slice's name).
    """
    s = _Summaries(source)
    m = len(s)
    cfg = s.config
    if coords is None:
        coords = s.coords
    c = _coords(coords, m)
    sets_arr = pa.ListArray.from_arrays(
        pa.array(s.set_offsets.astype(np.int32), type=pa.int32()), pa.array(s.sets, type=pa.uint8())
    )
    cols = {
        "ic_id": pa.array(_ids(ic_ids, m), type=pa.int64()),
        **c,
        **{name: pa.array(np.ascontiguousarray(s.ics[:, j])) for j, name in enumerate(("vx", "vy", "vz", "Lx", "Ly", "Lz"))},
        "preset": _const_str(cfg.preset.name, m),
        "integrator": _const_str(cfg.numerics.integrator, m),
        "dt_s": pa.array(np.full(m, cfg.numerics.dt_s), type=pa.float64()),
        "outcome": pa.array(s.outcome, type=pa.int8()),
        "status": pa.DictionaryArray.from_arrays(
            pa.array(s.status_code.astype(np.int8)), pa.array(list(LABELS))
        ).cast(pa.string()),
        "steps": pa.array(s.steps, type=pa.int64()),
        "t_settle_s": pa.array(s.t_settle_s, type=pa.float64()),
        "contact_sets": sets_arr,
        "contact_sequence": sequences_array(s.sets, s.set_offsets),
        "n_contact_changes": pa.array((np.diff(s.set_offsets) - 1).astype(np.int32)),
    }
    schema = ROLLS_SCHEMA
    if index is not None:
        idx = np.asarray(index, dtype=np.int32).reshape(m, 3)
        cols.update({name: pa.array(np.ascontiguousarray(idx[:, j])) for j, name in enumerate("ijk")})
        schema = GRID_ROLLS_SCHEMA
    if s.set_times is not None:
        cols["contact_times_s"] = pa.ListArray.from_arrays(
            pa.array(s.set_offsets.astype(np.int32), type=pa.int32()), pa.array(s.set_times, type=pa.float64()))
        schema = schema.append(EVENT_TIMES_FIELD)
    if s.orientations is not None:
        for j, name in enumerate(("qx", "qy", "qz", "qw")):
            cols[name] = pa.array(np.ascontiguousarray(s.orientations[:, j]), type=pa.float64())
        cols["z0_cm"] = pa.array(np.asarray(s.heights_cm, dtype=np.float64), type=pa.float64())
        for f in POSE_FIELDS:
            schema = schema.append(f)
    table = pa.Table.from_arrays([cols[f.name] for f in schema], schema=schema)
    device = getattr(source, "device", None)  # where a batch ran (BatchResult.device)
    extra = {"device": device, **dict(metadata or {})} if device is not None else metadata
    return _with_metadata(table, metadata_json(cfg, s.ics, extra=extra))


def contacts_table(source, *, ic_ids=None, metadata: Mapping | None = None) -> pa.Table:
    """The ``contacts`` table: one row per node entering or leaving contact (z ≤ 0).

    ``source`` as for :func:`rolls_table`; events are ordered by IC, step, node.
    """
    s = _Summaries(source)
    ids = _ids(ic_ids, len(s))
    row, step, t_s, node, entered = s.events()
    cols = [
        pa.array(ids[row], type=pa.int64()),
        pa.array(step, type=pa.int64()),
        pa.array(t_s, type=pa.float64()),
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
    rows = tr.written  # a failed run may leave its last row unwritten
    n = int(rows.sum())
    cols: dict[str, np.ndarray] = {
        "ic_id": np.full(n, int(ic_id), dtype=np.int64),
        "step": tr.step[rows].astype(np.int64),
        "t_s": tr.t_s[rows].astype(np.float64),
    }
    for j, a in enumerate("xyz"):
        cols[f"cm_{a}_cm"] = tr.cm_pos[rows, j]
        cols[f"vcm_{a}_cm_s"] = tr.cm_vel[rows, j]
    q = tr.quat_xyzw[rows]
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
    # + 0.0 turns a negative zero (a sign flipped on 0, as the L convention does) into 0.0: readers print -0.0
    arrays = [pa.array(np.ascontiguousarray(cols[f.name]) + 0.0 if pa.types.is_floating(f.type) else cols[f.name],
                       type=f.type) for f in TRAJECTORY_SCHEMA]
    table = pa.Table.from_arrays(arrays, schema=TRAJECTORY_SCHEMA)
    return _with_metadata(table, metadata_json(roll.config, roll.ic, extra=metadata))
