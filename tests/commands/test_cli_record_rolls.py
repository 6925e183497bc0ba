"""``dicetrace record --rolls FILE --ic-id N``: a row of a rolls table recorded again, pose and body included."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from dicetrace.params import make_config
from dicetrace.simulate import simulate_batch
from dicetrace.sinks.parquet import write_tables
from dicetrace.throws import CASUAL

rr = pytest.importorskip("rerun")


@pytest.fixture(scope="module")
def table(tmp_path_factory):
    """Six hand throws of a flat box, each from its own pose, written as tables."""
    cfg = make_config("physical", half_extents_cm=(1.0, 1.0, 0.6))
    t = CASUAL.sample(6, cfg, 1)
    b = simulate_batch(t.ics, config=cfg, orientations=t.orientations, heights_cm=t.heights_cm)
    folder = tmp_path_factory.mktemp("rolls")
    paths = write_tables(folder / "tab", b)
    return paths["rolls"], b, t


def test_a_row_replays_as_the_throw_it_records_from_its_pose(table, tmp_path, dicetrace_cli):
    from dicetrace.sinks.rerun import read_rrd, read_rrd_metadata

    path, b, t = table
    i = 3
    out = tmp_path / "row.rrd"
    res = dicetrace_cli("record", "--rolls", str(path), "--ic-id", str(i), "--out", str(out), cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert "ends otherwise" not in res.stderr
    assert f"outcome {b.outcome[i]}  status settled  steps {b.steps[i]} " in res.stdout
    meta = read_rrd_metadata(out)
    assert meta["config"]["preset"]["half_extents_cm"] == [1.0, 1.0, 0.6]
    # the recording starts in the row's pose, at its height
    box = read_rrd(out)["/world/die/body"]
    q0 = np.array(box.column("Boxes3D:quaternions").to_pylist()[0][0], dtype=np.float64)
    np.testing.assert_allclose(Rotation.from_quat(q0).as_matrix(), Rotation.from_quat(t.orientations[i]).as_matrix(),
                               atol=1e-6)
    c0 = np.array(box.column("Boxes3D:centers").to_pylist()[0][0])
    assert c0[2] == pytest.approx(t.heights_cm[i], abs=1e-5)


@pytest.mark.parametrize("args, message", [
    (["--ic-id", "99"], "--ic-id 99: the table"),
    (["--ic-id", "1", "--preset", "seed"], "--rolls takes the IC and the configuration from the table: drop --preset"),
    (["--ic-id", "1", "--ic", "1,2,3,4,5,6"], "give either --rolls FILE --ic-id N or --ic"),
    ([], "--rolls needs --ic-id N"),
])
def test_bad_replays_are_one_line(table, tmp_path, dicetrace_cli, args, message):
    path, _, _ = table
    res = dicetrace_cli("record", "--rolls", str(path), *args, cwd=tmp_path)
    assert res.returncode == 2 and message in res.stderr and res.stderr.count("\n") == 1
    assert not (tmp_path / "recordings").exists()


def test_ic_id_without_a_table_and_a_file_that_is_no_table_are_refused(tmp_path, dicetrace_cli):
    res = dicetrace_cli("record", "--ic-id", "1", cwd=tmp_path)
    assert res.returncode == 2 and "--ic-id needs --rolls FILE" in res.stderr
    (tmp_path / "x.parquet").write_text("no table")
    res = dicetrace_cli("record", "--rolls", str(tmp_path / "x.parquet"), "--ic-id", "1", cwd=tmp_path)
    assert res.returncode == 2 and res.stderr.startswith("dicetrace: error: --rolls") and res.stderr.count("\n") == 1


@pytest.fixture(scope="module")
def hand_scan(tmp_path_factory):
    """Eight hand throws of a flat box scanned into a folder (two chunks), each from its own pose."""
    from dicetrace.scan import scan
    from dicetrace.scan.poses import HandThrows

    folder = tmp_path_factory.mktemp("scan") / "hand"
    scan(HandThrows("vigorous", 8, 4), folder, config=make_config("physical", half_extents_cm=(1.0, 1.0, 0.6)),
         chunk=4)
    return folder


@pytest.mark.parametrize("where", ["folder", "chunk file"])
def test_a_scan_row_replays_from_the_scan_folder_or_its_chunk_file(hand_scan, tmp_path, dicetrace_cli, where):
    from dicetrace.scan import read_scan_table

    rows = {r["ic_id"]: r for r in read_scan_table(hand_scan).to_pylist()}
    i = 6
    path = hand_scan if where == "folder" else hand_scan / "rolls" / "part-000001.parquet"
    res = dicetrace_cli("record", "--rolls", str(path), "--ic-id", str(i), "--out", str(tmp_path / "r.rrd"),
                        cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert "ends otherwise" not in res.stderr
    r = rows[i]
    assert f"outcome {r['outcome']}  status {r['status']}  steps {r['steps']}  t_settle_s {r['t_settle_s']:g} " \
        in res.stdout, res.stdout
    res = dicetrace_cli("record", "--rolls", str(hand_scan), "--ic-id", "8", cwd=tmp_path)
    assert res.returncode == 2 and res.stderr.count("\n") == 1 and "--ic-id 8: the scan" in res.stderr
    assert not (tmp_path / "recordings").exists()
