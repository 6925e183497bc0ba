"""The Parquet sink: rolls, contacts and trajectory tables round-trip through pandas and pyarrow."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

import dicetrace
from dicetrace.ics import seed_slice
from dicetrace.simulate import Record, simulate, simulate_batch
from dicetrace.sinks import parquet as sink

SEQ_1_65_3_9 = "0-6-68-8-0-3-0-1-0-8-48-4-24-2-0-2-4-0-6-0-48-0-6"
# the writeup's three topology ICs on the seed slice
TOPOLOGY_XY = np.array([[1.65, 3.9], [1.5, 4.0], [1.2, 4.4]])


@pytest.fixture(scope="module")
def roll():
    return simulate(seed_slice(1.65, 3.9), record=Record(states=True, energy=True))


@pytest.fixture(scope="module")
def written(roll, tmp_path_factory):
    d = tmp_path_factory.mktemp("pq")
    paths = sink.write_tables(d, roll, coords=[[1.65, 3.9]], ic_ids=[7], metadata={"slice": "seed"})
    return d, paths


def test_writes_three_files_and_the_note_and_nothing_else(written):
    d, paths = written
    assert sorted(p.name for p in d.iterdir()) == [
        "README-tables.txt", "contacts.parquet", "rolls.parquet", "trajectory.parquet"
    ]
    assert set(paths) == {"rolls", "contacts", "trajectory"}
    assert (d / sink.NOTE_NAME).read_text() == sink.NOTE_TEXT


def test_schemas_are_the_declared_ones(written):
    d, _ = written
    for name, schema in (
        ("rolls", sink.ROLLS_SCHEMA),
        ("contacts", sink.CONTACTS_SCHEMA),
        ("trajectory", sink.TRAJECTORY_SCHEMA),
    ):
        got = pq.read_schema(d / f"{name}.parquet")
        assert got.remove_metadata().equals(schema.remove_metadata()), name
    rolls = pq.read_schema(d / "rolls.parquet")
    assert rolls.field("contact_sets").type == pa.list_(pa.uint8())
    assert rolls.field("outcome").type == pa.int8()
    assert rolls.field("t_settle_s").metadata[b"unit"] == b"s"
    traj = pq.read_schema(d / "trajectory.parquet")
    assert traj.names[:3] == ["ic_id", "step", "t_s"]
    assert "n8_z_cm" in traj.names and "vcm_x_cm_s" in traj.names and "e_total" in traj.names


def test_metadata_has_config_ics_and_version(roll, written):
    d, _ = written
    for name in ("rolls", "contacts", "trajectory"):
        raw = pq.read_schema(d / f"{name}.parquet").metadata[b"dicetrace"]
        meta = json.loads(raw)
        assert meta["dicetrace_version"] == dicetrace.__version__
        assert meta["config"] == json.loads(json.dumps(roll.config.as_dict()))
        assert meta["ics"] == [roll.ic.tolist()]
        assert meta["l_convention"] == "program"
        assert meta["slice"] == "seed"
        assert sink.read_metadata(d / f"{name}.parquet") == meta


def test_rolls_row_equals_the_roll(roll, written):
    d, _ = written
    df = pd.read_parquet(d / "rolls.parquet")
    assert len(df) == 1
    row = df.iloc[0]
    assert row["ic_id"] == 7
    assert (row["x"], row["y"]) == (1.65, 3.9) and np.isnan(row["z"])
    np.testing.assert_array_equal(row[["vx", "vy", "vz", "Lx", "Ly", "Lz"]].to_numpy(dtype=float), roll.ic)
    assert (row["preset"], row["integrator"], row["dt_s"]) == ("seed", "semi-implicit-euler", 0.001)
    assert row["outcome"] == roll.outcome == 3
    assert row["status"] == "settled"
    assert row["steps"] == roll.steps and row["t_settle_s"] == roll.t_settle_s
    np.testing.assert_array_equal(row["contact_sets"], roll.contact_sets)
    assert row["contact_sequence"] == roll.contact_sequence == SEQ_1_65_3_9
    assert row["n_contact_changes"] == roll.n_contact_changes
    assert df["outcome"].dtype == np.int8


def test_contacts_equal_the_roll_events(roll, written):
    d, _ = written
    df = pd.read_parquet(d / "contacts.parquet")
    ev = roll.contact_events()
    assert (df["ic_id"] == 7).all()
    np.testing.assert_array_equal(df["step"].to_numpy(), ev["step"].to_numpy())
    np.testing.assert_array_equal(df["t_s"].to_numpy(), ev["t_s"].to_numpy())
    np.testing.assert_array_equal(df["node"].to_numpy(), ev["node"].to_numpy())
    np.testing.assert_array_equal(df["kind"].to_numpy(dtype=object), ev["kind"].to_numpy(dtype=object))


def test_trajectory_equals_the_trace(roll, written):
    d, _ = written
    df = pd.read_parquet(d / "trajectory.parquet")
    tr = roll.trace
    assert len(df) == roll.steps + 1
    np.testing.assert_array_equal(df["step"].to_numpy(), np.arange(roll.steps + 1))
    np.testing.assert_array_equal(df["t_s"].to_numpy(), tr.t_s)
    np.testing.assert_array_equal(df[["cm_x_cm", "cm_y_cm", "cm_z_cm"]].to_numpy(), tr.cm_pos)
    np.testing.assert_array_equal(df[["vcm_x_cm_s", "vcm_y_cm_s", "vcm_z_cm_s"]].to_numpy(), tr.cm_vel)
    np.testing.assert_array_equal(df[["Lx", "Ly", "Lz"]].to_numpy(), tr.L)
    nodes = df[[f"n{k}_{a}_cm" for k in range(1, 9) for a in "xyz"]].to_numpy().reshape(-1, 8, 3)
    np.testing.assert_array_equal(nodes, tr.node_pos)
    for key, col in (
        ("stop_test", "e_stop_test"),
        ("kinetic_translational", "e_kin_trans"),
        ("kinetic_rotational", "e_kin_rot"),
        ("gravitational", "e_grav"),
        ("elastic", "e_elastic"),
        ("total", "e_total"),
    ):
        np.testing.assert_array_equal(df[col].to_numpy(), tr.energy[key])
    q = df[["qx", "qy", "qz", "qw"]].to_numpy()
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-12)
    from scipy.spatial.transform import Rotation

    rotated = np.einsum("nij,kj->nki", Rotation.from_quat(q).as_matrix(), tr.node_offsets[0])
    np.testing.assert_allclose(rotated, tr.node_offsets, atol=1e-9)


def test_plain_pandas_reads_the_files_without_dicetrace(written):
    d, _ = written
    code = (
        "import sys, pandas as pd\n"
        f"d = {str(d)!r}\n"
        "for n in ('rolls', 'contacts', 'trajectory'):\n"
        "    df = pd.read_parquet(f'{d}/{n}.parquet')\n"
        "    assert len(df) > 0, n\n"
        "assert 'dicetrace' not in sys.modules\n"
        "print(pd.read_parquet(f'{d}/rolls.parquet')['contact_sequence'][0])\n"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == SEQ_1_65_3_9


def test_batch_rolls_table_matches_single_throws(tmp_path):
    ics = seed_slice(TOPOLOGY_XY[:, 0], TOPOLOGY_XY[:, 1])
    batch = simulate_batch(ics)
    table = sink.rolls_table(batch, coords=TOPOLOGY_XY, ic_ids=[10, 11, 12])
    assert table.schema.remove_metadata().equals(sink.ROLLS_SCHEMA.remove_metadata())
    df = table.to_pandas()
    np.testing.assert_array_equal(df["ic_id"], [10, 11, 12])
    np.testing.assert_array_equal(df[["x", "y"]].to_numpy(), TOPOLOGY_XY)
    assert df["z"].isna().all()
    for i, ic in enumerate(ics):
        r = simulate(ic)
        assert df["outcome"][i] == r.outcome
        assert df["steps"][i] == r.steps
        assert df["status"][i] == r.status
        assert df["contact_sequence"][i] == r.contact_sequence
        np.testing.assert_array_equal(df["contact_sets"][i], r.contact_sets)
        assert df["n_contact_changes"][i] == r.n_contact_changes
    assert df["contact_sequence"][0] == SEQ_1_65_3_9
    meta = json.loads(table.schema.metadata[b"dicetrace"])
    assert meta["n_ics"] == 3 and len(meta["ics"]) == 3

    # contacts of a batch: the per-throw events, IC after IC
    contacts = sink.contacts_table(batch, ic_ids=[10, 11, 12]).to_pandas()
    for i, ic in enumerate(ics):
        ev = simulate(ic).contact_events()
        sub = contacts[contacts["ic_id"] == 10 + i]
        np.testing.assert_array_equal(sub["step"], ev["step"])
        np.testing.assert_array_equal(sub["node"], ev["node"])
        np.testing.assert_array_equal(sub["kind"].to_numpy(dtype=object), ev["kind"].to_numpy(dtype=object))

    # a batch has no trajectory
    paths = sink.write_tables(tmp_path, batch)
    assert sorted(paths) == ["contacts", "rolls"]


def test_coords_as_mapping_and_3d(tmp_path):
    xyz = np.array([[1.65, 3.9, 0.5]])
    r = simulate(seed_slice(*xyz[0]))
    df = sink.rolls_table(r, coords={"x": xyz[:, 0], "y": xyz[:, 1], "z": xyz[:, 2]}).to_pandas()
    np.testing.assert_array_equal(df[["x", "y", "z"]].to_numpy(), xyz)
    with pytest.raises(ValueError, match="coords"):
        sink.rolls_table(r, coords={"w": [1.0]})
    with pytest.raises(ValueError, match="ic_ids"):
        sink.rolls_table(r, ic_ids=[1, 2])


def test_write_is_atomic(roll, tmp_path, monkeypatch):
    (tmp_path / "rolls.parquet").write_bytes(b"old")
    real = pq.write_table
    calls = []

    def flaky(table, where, **kw):
        calls.append(where)
        if len(calls) == 2:
            raise OSError(28, "No space left on device")
        return real(table, where, **kw)

    monkeypatch.setattr(sink.pq, "write_table", flaky)
    with pytest.raises(OSError):
        sink.write_tables(tmp_path, roll)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rolls.parquet"]
    assert (tmp_path / "rolls.parquet").read_bytes() == b"old"


def test_failed_run_trajectory_has_only_written_rows(tmp_path):
    r = simulate(seed_slice(1.65, 3.9), dt_s=0.01, record=Record(states=True, energy=True))
    assert r.status == "blow_up"
    sink.write_tables(tmp_path, r)
    rolls = pd.read_parquet(tmp_path / "rolls.parquet")
    assert rolls["status"][0] == "blow_up" and rolls["outcome"][0] == -1
    traj = pd.read_parquet(tmp_path / "trajectory.parquet")
    assert 1 <= len(traj) <= r.steps + 1
    nodes = traj[[f"n{k}_{a}_cm" for k in range(1, 9) for a in "xyz"]].to_numpy()
    assert not (nodes == 0).all(axis=1).any()  # no unwritten (all-zero) state row


def test_exact_contact_events_round_trip_through_the_parquet_files(tmp_path):
    """With exact contact events the ``rolls`` file carries ``contact_times_s`` (the Roll's and the batch's times,
    bit for bit) and the ``contacts`` file's ``t_s`` are the events' own times, not step ends; read back with
    plain pandas.  Without events neither changes; rolls with and without events are refused in one table."""
    ics = np.array([[10.0, 0.0, 0.0, 300.0, 0.0, 0.0], [-40.0, 25.0, 30.0, 900.0, -1500.0, 400.0]])
    kw = dict(preset="physical", t_max_s=1.0)
    rolls = [simulate(ic, events=True, **kw) for ic in ics]
    batch = simulate_batch(ics, events=True, **kw)
    sink.write_tables(tmp_path / "one", rolls[1])
    sink.write_tables(tmp_path / "batch", batch)
    one = pd.read_parquet(tmp_path / "one" / "rolls.parquet")
    assert list(one["contact_times_s"][0]) == rolls[1].contact_times.tolist()
    got = pd.read_parquet(tmp_path / "batch" / "rolls.parquet")
    for i, r in enumerate(rolls):
        assert list(got["contact_times_s"][i]) == r.contact_times.tolist()
        assert got["contact_sequence"][i] == r.contact_sequence
    contacts = pd.read_parquet(tmp_path / "batch" / "contacts.parquet")
    first = contacts[contacts["ic_id"] == 0]
    starts = rolls[0].contact_times[1:]  # every set after the first empty one begins with an enter or a leave
    assert set(first["t_s"]) == set(starts.tolist())
    ev = rolls[0].contact_events()  # the Roll's own per-node events, exact times included
    np.testing.assert_array_equal(first["t_s"].to_numpy(), ev["t_s"].to_numpy())
    np.testing.assert_array_equal(first["node"].to_numpy(), ev["node"].to_numpy())
    dt = batch.config.numerics.dt_s
    assert not np.allclose(first["t_s"], first["step"] * dt)  # exact times, not the ends of the steps
    assert np.all((first["t_s"] > (first["step"] - 1) * dt) & (first["t_s"] < first["step"] * dt + dt))
    plain = sink.tables_for(simulate(ics[0], **kw))
    assert "contact_times_s" not in plain["rolls"].column_names
    with pytest.raises(ValueError, match="with and without exact contact events"):
        sink.tables_for([rolls[0], simulate(ics[1], **kw)])
