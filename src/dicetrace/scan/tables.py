"""Summaries of a batch of throws → the ``rolls`` Arrow table, vectorised.

The columns are DESIGN.md section 6's ``rolls`` table (``dicetrace.sinks.parquet.ROLLS_SCHEMA``, the
same fields, types and units) plus the grid
indices ``i, j, k`` (int32; k = 0 on 2-D grids, -1 for ICs that are not on
a grid).  Everything is built column-wise: the contact-set lists share one
flat uint8 buffer, and their text form (``0-6-68-...``) is written by a
small numba kernel straight into an Arrow string buffer, so tabulating
costs a few percent of simulating.
"""

from __future__ import annotations

import numba
import numpy as np
import pyarrow as pa

from dicetrace.core._jit import jit
from dicetrace.core.loop import run_batch
from dicetrace.core.model import BUFFER_FULL

from dicetrace.sinks.parquet import ROLLS_SCHEMA as SINK_ROLLS_SCHEMA

STATUS_NAMES = ("settled", "time_cap", "non_finite", "blow_up")
DEFAULT_CAP = 128  # contact sets per IC in the first pass (longer throws are re-run with more)


# The sink's rolls schema with the grid indices i, j, k after ic_id.
_GRID_FIELDS = [pa.field(name, pa.int32(), nullable=False) for name in ("i", "j", "k")]
ROLLS_SCHEMA = pa.schema([SINK_ROLLS_SCHEMA.field(0), *_GRID_FIELDS, *list(SINK_ROLLS_SCHEMA)[1:]])

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


class _Threads:
    """Context: numba threads for this thread's parallel regions (None: leave as is)."""

    def __init__(self, n: int | None):
        self.n = n

    def __enter__(self):
        self.old = numba.get_num_threads()
        if self.n is not None:
            numba.set_num_threads(max(1, min(int(self.n), numba.config.NUMBA_NUM_THREADS)))

    def __exit__(self, *exc):
        numba.set_num_threads(self.old)


def run_summaries(kics: np.ndarray, off0: np.ndarray, kp, integ: int, *, cap: int = DEFAULT_CAP, threads: int | None = None):
    """Summaries of every row of ``kics`` (kernel convention) with the batch kernel.

    Returns (status int8, steps int64, outcome int8, set_offsets int64 (m+1,),
    sets uint8).  Throws with more than ``cap`` contact sets are re-run with
    a larger buffer (same kernel, same bits).  Blocks of ICs are scheduled
    dynamically over the threads; results do not depend on how.
    """
    kics = np.ascontiguousarray(kics, dtype=np.float64)
    m = len(kics)
    status = np.zeros(m, dtype=np.int8)
    steps = np.zeros(m, dtype=np.int64)
    outcome = np.zeros(m, dtype=np.int8)
    nsets = np.zeros(m, dtype=np.int64)
    sets = np.zeros(m * cap, dtype=np.uint8)
    set_steps = np.zeros(m * cap, dtype=np.int32)
    if m:
        with _Threads(threads), numba.parallel_chunksize(1):
            run_batch(kics, off0, kp, integ, cap, status, steps, outcome, nsets, sets, set_steps)
    sets2 = sets.reshape(m, cap)
    extra: dict[int, np.ndarray] = {}
    todo = np.nonzero(status == BUFFER_FULL)[0]
    big = cap
    while todo.size:
        big *= 8
        st, sp, oc, ns, ss = (np.zeros(len(todo), np.int8), np.zeros(len(todo), np.int64),
                              np.zeros(len(todo), np.int8), np.zeros(len(todo), np.int64),
                              np.zeros(len(todo) * big, np.uint8))
        with _Threads(threads), numba.parallel_chunksize(1):
            run_batch(kics[todo], off0, kp, integ, big, st, sp, oc, ns, ss, np.zeros(len(todo) * big, np.int32))
        done = st != BUFFER_FULL
        for r in np.nonzero(done)[0]:
            i = todo[r]
            status[i], steps[i], outcome[i], nsets[i] = st[r], sp[r], oc[r], ns[r]
            extra[int(i)] = ss[r * big : r * big + ns[r]].copy()
        todo = todo[~done]
    offsets = np.zeros(m + 1, dtype=np.int64)
    np.cumsum(nsets, out=offsets[1:])
    if not extra:
        flat = sets2[np.arange(cap)[None, :] < nsets[:, None]]
    else:
        flat = np.empty(int(offsets[-1]), dtype=np.uint8)
        for i in range(m):
            src = extra[i] if i in extra else sets2[i, : nsets[i]]
            flat[offsets[i] : offsets[i + 1]] = src
    return status, steps, outcome, offsets, flat


def rolls_table(
    *,
    ic_id: np.ndarray,
    index: np.ndarray,
    coords: np.ndarray,
    ics: np.ndarray,
    config,
    status: np.ndarray,
    steps: np.ndarray,
    outcome: np.ndarray,
    set_offsets: np.ndarray,
    sets: np.ndarray,
) -> pa.Table:
    """The ``rolls`` table (``ROLLS_SCHEMA``) from summary arrays.

    ``coords`` (m, 3) slice coordinates, NaN → null; ``index`` (m, 3) int32;
    ``ics`` (m, 6) in the preset's L convention.
    """
    m = len(ic_id)
    dt = config.numerics.dt_s
    coords = np.asarray(coords, dtype=np.float64).reshape(m, 3)
    index = np.asarray(index, dtype=np.int32).reshape(m, 3)
    ics = np.asarray(ics, dtype=np.float64).reshape(m, 6)

    def const_str(v: str) -> pa.Array:
        return pa.DictionaryArray.from_arrays(pa.array(np.zeros(m, np.int8)), pa.array([v])).cast(pa.string())

    def coord(j: int) -> pa.Array:
        col = coords[:, j]
        nan = np.isnan(col)
        return pa.array(col, type=pa.float64(), mask=nan if nan.any() else None)

    cols = [
        pa.array(np.asarray(ic_id, dtype=np.int64)),
        pa.array(np.ascontiguousarray(index[:, 0])),
        pa.array(np.ascontiguousarray(index[:, 1])),
        pa.array(np.ascontiguousarray(index[:, 2])),
        coord(0),
        coord(1),
        coord(2),
        *[pa.array(np.ascontiguousarray(ics[:, j])) for j in range(6)],
        const_str(config.preset.name),
        const_str(config.numerics.integrator),
        pa.array(np.full(m, dt)),
        pa.array(np.asarray(outcome, dtype=np.int8)),
        pa.DictionaryArray.from_arrays(
            pa.array(np.asarray(status, dtype=np.int8)), pa.array(list(STATUS_NAMES))
        ).cast(pa.string()),
        pa.array(np.asarray(steps, dtype=np.int64)),
        pa.array(np.asarray(steps, dtype=np.int64) * dt),
        pa.ListArray.from_arrays(
            pa.array(np.asarray(set_offsets, dtype=np.int32)), pa.array(np.asarray(sets, dtype=np.uint8))
        ),
        sequences_array(sets, set_offsets),
        pa.array((np.diff(set_offsets) - 1).astype(np.int32)),
    ]
    return pa.Table.from_arrays(cols, schema=ROLLS_SCHEMA)
