"""Scans of full starting states (``dicetrace.scan.poses``): hand throws drawn from a model, a throw table's rows.

Each throw from its own orientation and height, resumable, on Dask like any scan; the rows carry the pose and
replay exactly (``scan_row`` + ``simulate``, and ``dicetrace record --rolls SCAN --ic-id N``)."""

from __future__ import annotations

import sys

import numpy as np
import pyarrow.csv as pacsv
import pyarrow.parquet as pq
import pytest

from dicetrace.ic_arrays import validate_orientations
from dicetrace.params import make_config
from dicetrace.scan import ScanDefinition, read_scan_table, scan, scan_definition
from dicetrace.scan.poses import POSE_BLOCK, THROW_COLUMNS, HandThrows, ThrowTable, read_throw_table
from dicetrace.scan.read import scan_row
from dicetrace.simulate import simulate, simulate_batch
from dicetrace.throws import CASUAL, GENTLE

BOX = make_config("physical", half_extents_cm=(1.0, 1.0, 1.5))
#: 30 casual throws of a box 2 × 2 × 3 cm, seed 2, in chunks of 12 (3 chunks).
HAND = ["--preset", "physical", "--die", "2,2,3", "--throw", "casual", "--n", "30", "--seed", "2", "--chunk", "12"]
SUMMARY = ["ic_id", "vx", "vy", "vz", "Lx", "Ly", "Lz", "outcome", "status", "steps", "t_settle_s", "contact_sequence"]


def _cli(*args: str) -> int:
    from dicetrace.cli import app
    from dicetrace.commands._common import run_app

    argv, sys.argv = sys.argv, ["dicetrace", *args]
    try:
        with pytest.raises(SystemExit) as exc:
            run_app(app)
    finally:
        sys.argv = argv
    return int(exc.value.code or 0)


@pytest.fixture(scope="module")
def hand_scan(tmp_path_factory):
    folder = tmp_path_factory.mktemp("hand") / "scan"
    assert _cli("scan", *HAND, "-q", "--out", str(folder)) == 0
    return folder


def test_hand_throws_draw_any_range_again_bit_for_bit_whatever_the_chunking():
    space = HandThrows("casual", POSE_BLOCK + 100, seed=5)
    whole = space.block(0, space.n, BOX)
    part = space.block(POSE_BLOCK - 30, POSE_BLOCK + 20, BOX)  # across two blocks
    for name in ("ics", "orientations", "heights_cm"):
        np.testing.assert_array_equal(getattr(part, name), getattr(whole, name)[POSE_BLOCK - 30: POSE_BLOCK + 20])
    np.testing.assert_array_equal(part.ic_id, np.arange(POSE_BLOCK - 30, POSE_BLOCK + 20))
    assert (part.index == -1).all() and np.isnan(part.coords).all()
    # block b is the model's own draw of POSE_BLOCK throws from the seed [seed, b]
    t = CASUAL.sample(POSE_BLOCK, BOX, [5, 1])
    np.testing.assert_array_equal(whole.ics[POSE_BLOCK:], t.ics[:100])
    # another seed, another model: other throws; the die's inertia is in L
    assert not np.array_equal(HandThrows("casual", 50, 6).block(0, 50, BOX).ics, whole.ics[:50])
    assert not np.array_equal(HandThrows(GENTLE, 50, 5).block(0, 50, BOX).ics, whole.ics[:50])
    assert not np.array_equal(space.block(0, 50, make_config("physical")).ics, whole.ics[:50])


def test_a_definition_of_throws_round_trips_and_runs_on_the_cpu_only():
    from dicetrace.params import ConfigError

    defn = ScanDefinition(HandThrows("vigorous", 10, 3), BOX, 4)
    again = ScanDefinition.from_dict(defn.to_dict())
    assert again == defn and again.digest() == defn.digest() and again.posed
    assert [f.name for f in defn.schema][-5:] == ["qx", "qy", "qz", "qw", "z0_cm"]
    with pytest.raises(ConfigError, match="run on the CPU"):
        ScanDefinition(HandThrows("casual", 10), BOX, 4, device="cuda: a GPU")


@pytest.mark.slow
def test_a_hand_throw_scan_is_simulate_batch_of_its_throws_from_their_poses(hand_scan):
    t = HandThrows("casual", 30, 2).block(0, 30, BOX)
    want = simulate_batch(t.ics, config=BOX, orientations=t.orientations, heights_cm=t.heights_cm).to_arrow()
    got = read_scan_table(hand_scan)
    for c in SUMMARY:
        assert got.column(c).to_pylist() == want.column(c).to_pylist(), c
    pose = np.stack([got.column(c).to_numpy() for c in ("qx", "qy", "qz", "qw", "z0_cm")], axis=1)
    np.testing.assert_array_equal(pose, np.c_[t.orientations, t.heights_cm])  # each pose as it was drawn
    assert len(set(got.column("outcome").to_pylist())) >= 4


@pytest.mark.slow
def test_every_row_of_a_hand_throw_scan_replays_exactly(hand_scan):
    rows = read_scan_table(hand_scan).to_pylist()
    for r in rows:
        cfg, row = scan_row(hand_scan, r["ic_id"])
        assert row == r
        R = validate_orientations(np.array([[row[c] for c in ("qx", "qy", "qz", "qw")]]), 1)[0]
        cfg = type(cfg)(preset=cfg.preset.with_(z0_cm=row["z0_cm"]), numerics=cfg.numerics)
        roll = simulate([row[c] for c in ("vx", "vy", "vz", "Lx", "Ly", "Lz")], config=cfg, orientation=R)
        assert (roll.outcome, roll.steps, roll.t_settle_s, roll.contact_sequence) == \
            (row["outcome"], row["steps"], row["t_settle_s"], row["contact_sequence"])
    assert scan_row(hand_scan, 30) == (scan_definition(hand_scan).config, None)


@pytest.mark.slow
def test_an_interrupted_hand_throw_scan_resumes_to_the_same_table(hand_scan, tmp_path, dicetrace_cli):
    out = tmp_path / "again"
    assert dicetrace_cli("scan", *HAND, "--max-chunks", "2", "-q", "--out", str(out), cwd=tmp_path).returncode == 0
    res = dicetrace_cli("scan", *HAND, "--out", str(out), cwd=tmp_path)
    assert res.returncode == 0 and "(1 computed, 2 already there" in res.stderr, res.stderr
    assert read_scan_table(out).equals(read_scan_table(hand_scan))
    other = [("3" if a == "2" and HAND[k - 1] == "--seed" else a) for k, a in enumerate(HAND)]  # another seed
    res = dicetrace_cli("scan", *other, "--out", str(out), cwd=tmp_path)
    assert res.returncode == 2 and "holds a different scan (space.seed: 2 vs 3)" in res.stderr


@pytest.mark.slow
def test_a_throw_table_scans_as_its_rows_from_parquet_and_from_csv(tmp_path, dicetrace_cli):
    t = CASUAL.sample(14, BOX, 9)
    b = simulate_batch(t.ics, config=BOX, orientations=t.orientations, heights_cm=t.heights_cm)
    from dicetrace.sinks.parquet import write_tables

    path = write_tables(tmp_path / "tab", b)["rolls"]
    space = read_throw_table(path, "program")
    assert space.n == 14 and space.l_convention == "physical"  # the table's metadata says its convention
    res = dicetrace_cli("scan", "--preset", "physical", "--die", "2,2,3", "--throws", str(path), "--chunk", "5", "-q",
                        "--out", str(tmp_path / "s"), cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    got = read_scan_table(tmp_path / "s")
    want = pq.read_table(path)
    for c in ["vx", "vy", "vz", "Lx", "Ly", "Lz", "qx", "qy", "qz", "qw", "z0_cm"]:
        assert got.column(c).to_pylist() == want.column(c).to_pylist(), c
    # the throws of the table (its poses made matrices again): those of simulate_batch from those poses
    again = simulate_batch(want.select(list(THROW_COLUMNS[:6])).to_pandas().to_numpy(), config=BOX,
                           orientations=want.select(["qx", "qy", "qz", "qw"]).to_pandas().to_numpy(),
                           heights_cm=want.column("z0_cm").to_numpy())
    assert got.column("outcome").to_pylist() == again.outcome.tolist()
    assert got.column("steps").to_pylist() == again.steps.tolist()
    # the same throws as a CSV (L in the preset's convention): the same rows
    csv_path = tmp_path / "throws.csv"
    pacsv.write_csv(want.select(list(THROW_COLUMNS)), csv_path)
    res = dicetrace_cli("scan", "--preset", "physical", "--die", "2,2,3", "--throws", str(csv_path), "--chunk", "5",
                        "-q", "--out", str(tmp_path / "c"), cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    got_csv = read_scan_table(tmp_path / "c")
    for c in SUMMARY + ["qx", "qy", "qz", "qw", "z0_cm"]:
        assert got_csv.column(c).to_pylist() == got.column(c).to_pylist(), c
    # the table changed since the scan began: a resume refuses it, naming --throws
    with open(csv_path, "a") as f:
        f.write("1,2,3,4,5,6,0,0,0,1,9\n")
    res = dicetrace_cli("scan", "--preset", "physical", "--die", "2,2,3", "--throws", str(csv_path), "--chunk", "5",
                        "-q", "--out", str(tmp_path / "c"), cwd=tmp_path)
    assert res.returncode == 2 and res.stderr.count("\n") == 1 and "different scan (space.n: 14 vs 15" in res.stderr
    with pytest.raises(ValueError, match="has changed since the scan began"):
        ThrowTable.from_dict(scan_definition(tmp_path / "c").space.to_dict()).block(0, 1)


CSV_HEAD = ",".join(THROW_COLUMNS) + "\n"


@pytest.mark.parametrize("text, message", [
    (CSV_HEAD + "1,2,3,4,5,6,0,0,0,1,0.5\n", "row 0 starts below the table with this die"),
    (CSV_HEAD + "1,2,3,4,5,6,0,0,0,2,5\n", "row 0's orientation qx, qy, qz, qw has norm 2, not 1"),
    (CSV_HEAD + "1,2,3,4,5,six,0,0,0,1,5\n", "a row has a value that is not a number"),
    (CSV_HEAD + "1,2,3,4,5,inf,0,0,0,1,5\n", "row 0 has a value that is not a finite number (Lz)"),
    (CSV_HEAD, "it has no rows"),
    ("vx,vy\n1,2\n", "it is neither Parquet nor a CSV file with the columns"),
])
def test_bad_throw_tables_are_refused_in_one_line_naming_the_option(tmp_path, dicetrace_cli, text, message):
    path = tmp_path / "t.csv"
    path.write_text(text)
    res = dicetrace_cli("scan", "--preset", "physical", "--throws", str(path), "--out", str(tmp_path / "o"),
                        cwd=tmp_path)
    assert res.returncode == 2 and res.stdout == "" and res.stderr.count("\n") == 1, res.stderr
    assert res.stderr.startswith(f"dicetrace: error: --throws {str(path)!r}: ") and message in res.stderr, res.stderr
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("args, message", [
    (["--throw", "wild", "--n", "3"], "--throw: unknown throw model 'wild' (choose from casual, gentle, vigorous)"),
    (["--throw", "casual"], "--throw needs --n N"),
    (["--throw", "casual", "--n", "0"], "--n: the number of throws n must be an integer >= 1, got 0"),
    (["--throw", "casual", "--n", "3", "--seed", "-1"], "--seed: the throws' seed must be an integer in [0, 2**63)"),
    (["--throw", "casual", "--n", "3", "--window", "home", "--res", "2"], "give one IC space: --window/--res or --throw"),
    (["--throw", "casual", "--n", "3", "--slice", "seed3"], "--slice gives a slice: --throw scans hand throws"),
    (["--throw", "casual", "--n", "3", "--box", "home"], "--box goes with a slice, not with --throw"),
    (["--throw", "casual", "--n", "3", "--rrd", "m.rrd"], "--rrd draws the scan map of a slice"),
    (["--throw", "casual", "--n", "3", "--png", "m.png"], "--png draws 2-D and 3-D grid scans only"),
    (["--throws", "t.csv", "--n", "3"], "--throws gives the throws: drop --n"),
    (["--throws", "none.csv"], "--throws 'none.csv': is not a file"),
    (["--n", "3"], "--n goes with --sample (random or sobol) or --throw (a hand-throw model), neither is given"),
])
def test_bad_throw_options_are_one_line(tmp_path, dicetrace_cli, args, message):
    (tmp_path / "t.csv").write_text(CSV_HEAD + "0,0,0,0,0,0,0,0,0,1,5\n")
    res = dicetrace_cli("scan", "--preset", "physical", *args, "--out", str(tmp_path / "o"), cwd=tmp_path)
    assert res.returncode == 2 and res.stdout == "" and res.stderr.count("\n") == 1, res.stderr
    assert res.stderr.startswith("dicetrace: error: " + message), res.stderr
    assert not (tmp_path / "o").exists()


@pytest.mark.long
def test_hand_throws_scan_on_dask_as_here(hand_scan, tmp_path):
    pytest.importorskip("distributed")
    report = scan(HandThrows("casual", 30, 2), tmp_path / "dask", config=BOX, chunk=12, dask=True, n_workers=1)
    assert report.complete
    assert read_scan_table(tmp_path / "dask").equals(read_scan_table(hand_scan))
