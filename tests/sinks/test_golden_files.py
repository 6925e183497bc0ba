"""Golden files: one throw's ``.rrd`` and its three Parquet tables, regenerated and compared value by value.

``tests/data/golden`` holds what ``dicetrace record --slice seed --at 1.65,3.9
--out seed_x1.65_y3.9.rrd --parquet DIR`` wrote (the red-sea throw, 540
steps; see the README there).  Every test run records the same throw again
into a temporary folder, through the same command (in-process), and compares:

* Parquet: schema (names, types, nullability, each field's unit metadata),
  the ``dicetrace`` schema metadata (config, ICs, label; all but the version
  string) and every column, floats bit for bit.
* ``.rrd``: every entity of the recording store (temporal and static), its
  component columns and their rerun descriptors, floats bit for bit; the
  ``dicetrace`` recording property; and the blueprint store (views, origins,
  containers, camera), with its random ids replaced by tree positions.
  Only what differs on every write is left out: row ids, chunk ids, the
  recording id and start time, the blueprint's ``log_time``, and the version.

``rerun rrd compare`` is not used: it compares floats with a tolerance (a
1e-3 cm change of the centre of mass passes it) and skips the blueprint.

Regenerate after an intended change: ``pytest --update-golden`` (or
``DICETRACE_UPDATE_GOLDEN=1 pytest``), then review ``git diff --stat
tests/data/golden`` and the test output of the next plain run.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import re
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

pytest.importorskip("rerun")

from rerun.chunk import RrdReader  # noqa: E402
from rrd_blueprint import VOLATILE_COLUMNS, blueprint_tree  # noqa: E402

GOLDEN = Path(__file__).resolve().parents[1] / "data" / "golden"
RRD_NAME = "seed_x1.65_y3.9.rrd"
TABLES = ("rolls", "contacts", "trajectory")
RECORD_ARGS = ("record", "--slice", "seed", "--at", "1.65,3.9")
MAX_TOTAL_BYTES = 1_000_000

# Written anew on every run, whatever the code: never compared.
_VERSION = "<version>"


# -- regenerating -----------------------------------------------------------------------------


def _record_into(folder: Path) -> None:
    """``dicetrace record`` of the golden throw into ``folder`` (in-process: the console script's run_app)."""
    from dicetrace.cli import app
    from dicetrace.commands._common import run_app

    argv = ["dicetrace", *RECORD_ARGS, "--out", str(folder / RRD_NAME), "--parquet", str(folder)]
    err = io.StringIO()
    with pytest.MonkeyPatch.context() as mp, contextlib.redirect_stderr(err):
        mp.setattr(sys, "argv", argv)
        with pytest.raises(SystemExit) as exc:
            run_app(app)
    assert exc.value.code in (0, None), f"dicetrace {' '.join(argv[1:])} exited with {exc.value.code}: {err.getvalue()}"


def _golden_names() -> list[str]:
    return [RRD_NAME, *(f"{t}.parquet" for t in TABLES)]


@pytest.fixture(scope="module")
def fresh(tmp_path_factory, update_golden) -> Path:
    """A folder with the golden throw recorded by this checkout; with --update-golden also copied into GOLDEN."""
    folder = tmp_path_factory.mktemp("golden")
    _record_into(folder)
    if update_golden:
        GOLDEN.mkdir(parents=True, exist_ok=True)
        for name in _golden_names():
            tmp = GOLDEN / f".{name}.{os.getpid()}.tmp"  # two xdist workers may both write: atomic renames
            tmp.write_bytes((folder / name).read_bytes())
            os.replace(tmp, GOLDEN / name)
    return folder


@pytest.fixture
def golden(fresh, update_golden) -> Path:
    if update_golden:
        pytest.skip(f"golden files regenerated in {GOLDEN}: review them with git diff")
    missing = [n for n in _golden_names() if not (GOLDEN / n).exists()]
    if missing:
        pytest.fail(f"golden file(s) {missing} missing in {GOLDEN}: run pytest --update-golden")
    return GOLDEN


# -- comparing tables column by column ----------------------------------------------------------


def _leaves(arr: pa.Array) -> pa.Array:
    while pa.types.is_list(arr.type) or pa.types.is_large_list(arr.type) or pa.types.is_fixed_size_list(arr.type):
        arr = arr.flatten()
    return arr


def _float_bits(arr: pa.Array) -> np.ndarray | None:
    """Bit patterns of the float leaves of a (nested) array, or None when it holds no floats."""
    leaf = _leaves(arr)
    if not pa.types.is_floating(leaf.type):
        return None
    a = leaf.fill_null(0).to_numpy(zero_copy_only=False)
    return a.view({2: np.uint16, 4: np.uint32, 8: np.uint64}[a.dtype.itemsize])


def _first_difference(a: pa.Array, b: pa.Array) -> str:
    la, lb = a.to_pylist(), b.to_pylist()
    for i, (x, y) in enumerate(zip(la, lb)):
        if repr(x) != repr(y):
            return f"first at row {i}: golden {x!r:.200} != new {y!r:.200}"
    return "only in their float bits (a signed zero or NaN)"


def table_differences(golden: pa.Table, new: pa.Table, what: str, *, field_metadata: bool = True) -> list[str]:
    """Everything that differs between two tables, one line each (empty: identical, floats bit for bit)."""
    out = []
    gf = [(f.name, str(f.type), f.nullable) for f in golden.schema]
    nf = [(f.name, str(f.type), f.nullable) for f in new.schema]
    if gf != nf:
        return [f"{what}: columns (name, type, nullable) differ: golden {gf} != new {nf}"]
    if golden.num_rows != new.num_rows:
        return [f"{what}: golden has {golden.num_rows} rows, new {new.num_rows}"]
    for i, name in enumerate(golden.column_names):
        g, n = golden.column(i).combine_chunks(), new.column(i).combine_chunks()
        if field_metadata and golden.schema.field(i).metadata != new.schema.field(i).metadata:
            out.append(
                f"{what}.{name}: field metadata golden {golden.schema.field(i).metadata} != new {new.schema.field(i).metadata}"
            )
        gb, nb = _float_bits(g), _float_bits(n)
        if not g.equals(n) or (gb is not None and not np.array_equal(gb, nb)):
            out.append(f"{what}.{name}: {_first_difference(g, n)}")
    return out


def assert_no_differences(diffs: list[str]) -> None:
    assert not diffs, "differs from the golden files (if intended: pytest --update-golden):\n" + "\n".join(diffs)


# -- Parquet ------------------------------------------------------------------------------------


def _metadata_without_version(table: pa.Table) -> tuple[dict, str]:
    md = dict(table.schema.metadata or {})
    meta = json.loads(md.pop(b"dicetrace"))
    version = meta.pop("dicetrace_version")
    return {"dicetrace": meta, **{k.decode(): v.decode() for k, v in md.items()}}, version


@pytest.mark.parametrize("name", TABLES)
def test_parquet_table_equals_golden(golden, fresh, name):
    import dicetrace

    want = pq.read_table(golden / f"{name}.parquet")
    got = pq.read_table(fresh / f"{name}.parquet")
    diffs = table_differences(want, got, name)
    want_md, want_version = _metadata_without_version(want)
    got_md, got_version = _metadata_without_version(got)
    assert got_version == dicetrace.__version__ and want_version
    for key in sorted(set(want_md["dicetrace"]) | set(got_md["dicetrace"])):
        a, b = want_md["dicetrace"].get(key, "<absent>"), got_md["dicetrace"].get(key, "<absent>")
        if a != b:
            diffs.append(f"{name}: metadata {key!r}: golden {a!r:.300} != new {b!r:.300}")
    want_md.pop("dicetrace"), got_md.pop("dicetrace")
    if want_md != got_md:
        diffs.append(f"{name}: other schema metadata golden {want_md} != new {got_md}")
    assert_no_differences(diffs)


# -- .rrd: the recording store --------------------------------------------------------------------


def _mask_version(table: pa.Table, column: str, fn) -> pa.Table:
    if column not in table.column_names:
        return table
    i = table.column_names.index(column)
    field = table.schema.field(i)
    rows = [None if r is None else [fn(s) for s in r] for r in table.column(i).to_pylist()]
    return table.set_column(i, field, pa.array(rows, type=field.type))


def recording_tables(path: Path) -> dict[str, pa.Table]:
    """The recording store as one canonical table per ``"static <entity>"`` / ``"temporal <entity>"``.

    Row ids, chunk ids and the start time are dropped, rows sorted by the
    timelines, columns by name; the version string is masked.
    """
    reader = RrdReader(str(path))
    (store,) = reader.recordings()
    parts: dict[str, list[pa.Table]] = {}
    for ch in reader.stream(store=store):
        t = pa.Table.from_batches([ch.to_record_batch()]).replace_schema_metadata(None)  # chunk id, entity
        t = t.drop_columns([c for c in t.column_names if c in VOLATILE_COLUMNS])
        index = [f.name for f in t.schema if (f.metadata or {}).get(b"rerun:kind") == b"index"]
        if len(t.column_names) == len(index):
            continue  # nothing left but timelines (the start-time property)
        key = f"{'static' if ch.is_static else 'temporal'} {ch.entity_path}"
        parts.setdefault(key, []).append(t)
    out = {}
    for key, tables in parts.items():
        if key.startswith("static") and len(tables) > 1:
            tables = sorted(tables, key=lambda t: repr(t.to_pylist()))
        t = pa.concat_tables(tables, promote_options="default") if len(tables) > 1 else tables[0]
        t = t.select(sorted(t.column_names))
        index = [f.name for f in t.schema if (f.metadata or {}).get(b"rerun:kind") == b"index"]
        if index:
            t = t.sort_by([(c, "ascending") for c in sorted(index)])
        t = _mask_version(t, "dicetrace_version", lambda s: _VERSION)
        t = _mask_version(t, "TextDocument:text", lambda s: re.sub(r"(\*\*dicetrace\*\* )\S+", r"\g<1>" + _VERSION, s))
        out[key] = t
    return out


def test_rrd_recording_equals_golden(golden, fresh):
    want = recording_tables(golden / RRD_NAME)
    got = recording_tables(fresh / RRD_NAME)
    diffs = []
    if sorted(want) != sorted(got):
        diffs.append(f"entities: only in golden {sorted(set(want) - set(got))}, only in new {sorted(set(got) - set(want))}")
    for key in sorted(set(want) & set(got)):
        diffs += table_differences(want[key], got[key], key)
    assert_no_differences(diffs)
    # the comparison saw the data that matters
    assert {"temporal /world/die/nodes", "temporal /contacts", "static /summary", "static /__properties/dicetrace"} <= set(want)


# -- .rrd: the blueprint store ----------------------------------------------------------------------


def test_rrd_blueprint_equals_golden(golden, fresh):
    want, got = blueprint_tree(golden / RRD_NAME), blueprint_tree(fresh / RRD_NAME)
    diffs = [f"blueprint entities only in golden {sorted(set(want) - set(got))}, only in new {sorted(set(got) - set(want))}"]
    diffs = diffs if set(want) != set(got) else []
    for key in sorted(set(want) & set(got)):
        if want[key] != got[key]:
            diffs.append(f"blueprint {key}: golden {want[key]} != new {got[key]}")
    assert_no_differences(diffs)
    assert not [k for k in want if "unreached" in k], "a blueprint entity is not reachable from the viewport"
    origins = {v["ViewBlueprint:space_origin"][0] for v in want.values() if "ViewBlueprint:space_origin" in v}
    assert origins == {"/world", "/energy", "/stop_test", "/stop_margin", "/contacts", "/summary"}


# -- the files themselves, and the comparison's own power ---------------------------------------------


def test_golden_files_are_small_and_documented():
    sizes = {n: (GOLDEN / n).stat().st_size for n in _golden_names() if (GOLDEN / n).exists()}
    assert sum(sizes.values()) < MAX_TOTAL_BYTES, sizes
    readme = (GOLDEN / "README.md").read_text()
    assert "--update-golden" in readme and "DICETRACE_UPDATE_GOLDEN=1" in readme
    assert " ".join(RECORD_ARGS) in readme


def test_golden_throw_is_the_documented_one(golden):
    """The golden rows are the program's red-sea throw, not whatever the code wrote once."""
    from dicetrace.ics import seed_slice

    rolls = pq.read_table(golden / "rolls.parquet").to_pylist()
    assert len(rolls) == 1
    r = rolls[0]
    assert (r["x"], r["y"], r["outcome"], r["steps"], r["status"]) == (1.65, 3.9, 3, 540, "settled")
    assert r["contact_sequence"] == "0-6-68-8-0-3-0-1-0-8-48-4-24-2-0-2-4-0-6-0-48-0-6"
    assert [r[k] for k in ("vx", "vy", "vz", "Lx", "Ly", "Lz")] == seed_slice(1.65, 3.9).tolist()
    assert pq.read_table(golden / "trajectory.parquet").num_rows == 541


def _nudge(table: pa.Table, column: str, row: int, fn) -> pa.Table:
    i = table.column_names.index(column)
    values = table.column(i).to_pylist()
    values[row] = fn(values[row])
    return table.set_column(i, table.schema.field(i), pa.array(values, type=table.schema.field(i).type))


def test_comparison_catches_one_ulp_and_a_signed_zero(golden):
    traj = pq.read_table(golden / "trajectory.parquet")
    assert table_differences(traj, traj, "trajectory") == []
    ulp = _nudge(traj, "cm_z_cm", 300, lambda v: float(np.nextafter(v, np.inf)))
    (msg,) = table_differences(traj, ulp, "trajectory")
    assert msg.startswith("trajectory.cm_z_cm: first at row 300")
    rec = recording_tables(golden / RRD_NAME)
    cm = rec["temporal /world/cm"]
    up = lambda v: [[v[0][0], v[0][1], float(np.nextafter(np.float32(v[0][2]), np.float32(np.inf)))]]  # noqa: E731
    moved = _nudge(cm, "Points3D:positions", 100, up)
    (msg,) = table_differences(cm, moved, "cm")
    assert "Points3D:positions: first at row 100" in msg
    signed = pa.table({"a": pa.array([1.0, 0.0])})
    assert pa.table({"a": pa.array([1.0, -0.0])}).equals(signed)  # what Arrow's equals alone would let through
    assert table_differences(signed, pa.table({"a": pa.array([1.0, -0.0])}), "t") == ["t.a: first at row 1: golden 0.0 != new -0.0"]
