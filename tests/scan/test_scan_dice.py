"""``dicetrace scan --die/--load``: a scan of any box or loaded die, resumable, its die in the definition and metadata."""

from __future__ import annotations

import json
import os

import pyarrow.parquet as pq
import pytest

from dicetrace.ics import Grid
from dicetrace.params import make_config
from dicetrace.scan import read_manifest, read_scan_table, scan, scan_definition
from dicetrace.scan.chunk_files import METADATA_KEY
from dicetrace.simulate import simulate_batch

#: A small grid of the home window, a box 2 × 2 × 3 cm: 12 throws in 3 chunks.
BOX = ["--preset", "physical", "--die", "2,2,3", "--window", "home", "--res", "4,3", "--chunk", "5", "-q"]
COLUMNS = ["ic_id", "vx", "vy", "vz", "Lx", "Ly", "Lz", "outcome", "status", "steps", "t_settle_s", "contact_sequence"]


def _files(folder) -> dict:
    """Every file under ``folder``: its bytes and modification time (to see that nothing changed)."""
    return {str(p.relative_to(folder)): (p.read_bytes(), p.stat().st_mtime_ns) for p in sorted(folder.rglob("*"))
            if p.is_file()}


@pytest.fixture(scope="module")
def box_scan(tmp_path_factory):
    """The box's scan, run once through the command line in this process."""
    import sys

    from dicetrace.cli import app
    from dicetrace.commands._common import run_app

    folder = tmp_path_factory.mktemp("box") / "scan"
    argv = sys.argv
    sys.argv = ["dicetrace", "scan", *BOX, "--out", str(folder)]
    try:
        with pytest.raises(SystemExit) as exc:
            run_app(app)
    finally:
        sys.argv = argv
    assert exc.value.code in (None, 0)
    return folder


@pytest.mark.slow
def test_a_box_scan_is_simulate_batch_of_its_ics_with_that_body_bit_for_bit(box_scan):
    cfg = make_config("physical", half_extents_cm=(1.0, 1.0, 1.5))
    blk = Grid("seed", "home", (4, 3)).block(0, 12)
    want = simulate_batch(blk.ics, config=cfg, l_convention="program").to_arrow(ic_ids=blk.ic_id)
    got = read_scan_table(box_scan)
    assert got.num_rows == 12
    for c in COLUMNS:
        assert got.column(c).to_pylist() == want.column(c).to_pylist(), c
    # and the box is not the cube: the cube's scan of the same ICs ends otherwise
    cube = simulate_batch(blk.ics, config=make_config("physical"), l_convention="program")
    assert cube.outcome.tolist() != got.column("outcome").to_pylist()


@pytest.mark.slow
def test_the_scan_carries_its_die_in_the_definition_the_manifest_and_every_chunk(box_scan):
    defn = scan_definition(box_scan)
    assert defn.config.preset.half_extents_cm == (1.0, 1.0, 1.5)
    die = {"sides_cm": [2.0, 2.0, 3.0], "half_extents_cm": [1.0, 1.0, 1.5], "load_fraction": 0.0,
           "load_cm": [0.0, 0.0, 0.0], "com_cm": [0.0, 0.0, 0.0], "cube": False}
    assert read_manifest(box_scan)["die"] == die
    parts = sorted((box_scan / "rolls").glob("part-*.parquet"))
    assert len(parts) == 3
    for p in parts:
        assert json.loads(pq.read_schema(p).metadata[METADATA_KEY])["die"] == die
    assert json.loads(read_scan_table(box_scan).schema.metadata[METADATA_KEY])["die"] == die


@pytest.mark.slow
def test_an_interrupted_box_scan_resumes_to_the_same_table(box_scan, tmp_path, dicetrace_cli):
    out = tmp_path / "resumed"
    res = dicetrace_cli("scan", *BOX, "--out", str(out), "--max-chunks", "1", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert len(list((out / "rolls").glob("part-*.parquet"))) == 1
    res = dicetrace_cli("scan", *BOX[:-1], "--out", str(out), cwd=tmp_path)  # the same scan, not quiet
    assert res.returncode == 0, res.stderr
    assert "(2 computed, 1 already there" in res.stderr
    assert read_scan_table(out).equals(read_scan_table(box_scan))


@pytest.mark.slow
def test_the_die_given_with_set_is_the_same_scan_and_the_cube_s_sides_are_the_cube(box_scan, tmp_path, dicetrace_cli):
    import shutil

    out = tmp_path / "copy"
    shutil.copytree(box_scan, out)
    sets = [a for a in BOX if a not in ("--die", "2,2,3")] + ["--set", "half_extents_cm=1,1,1.5"]
    res = dicetrace_cli("scan", *sets[:-3], *sets[-2:], "--out", str(out), cwd=tmp_path)  # without -q
    assert res.returncode == 0, res.stderr
    assert "(0 computed, 3 already there" in res.stderr
    # a cube scan resumes with --die 2,2,2: the preset's own cube, written one way
    cube = ["--preset", "physical", "--window", "home", "--res", "2", "--chunk", "2"]
    assert dicetrace_cli("scan", *cube, "--max-chunks", "1", "-q", "--out", str(tmp_path / "cube"), cwd=tmp_path).returncode == 0
    res = dicetrace_cli("scan", *cube, "--die", "2,2,2", "--out", str(tmp_path / "cube"), cwd=tmp_path)
    assert res.returncode == 0 and "(1 computed, 1 already there" in res.stderr, res.stderr
    assert scan_definition(tmp_path / "cube").config.preset.half_extents_cm is None


@pytest.mark.slow
@pytest.mark.parametrize("other, option, says", [
    (["--die", "2,2,3.5"], "--die", "resume it with --die 2,2,3,"),
    (["--die", "2,2,3", "--load", "0.2@0.5,0,0"], "--load", "this run: box 2 × 2 × 3 cm, load 0.2 of its mass at (0.5, 0, 0) cm"),
    ([], "--die", "this run: cube 2 × 2 × 2 cm"),
])
def test_resuming_with_another_die_is_refused_in_one_line_naming_the_option(box_scan, tmp_path, dicetrace_cli, other,
                                                                            option, says):
    before = _files(box_scan)
    args = [a for a in BOX if a not in ("--die", "2,2,3")] + other
    res = dicetrace_cli("scan", *args, "--out", str(box_scan), cwd=tmp_path)
    assert res.returncode == 2 and res.stdout == ""
    assert res.stderr.count("\n") == 1 and res.stderr.startswith(f"dicetrace: error: {option}: "), res.stderr
    assert "holds a scan of another die (box 2 × 2 × 3 cm;" in res.stderr and says in res.stderr
    assert _files(box_scan) == before  # nothing written, nothing touched


@pytest.mark.parametrize("args, message", [
    (["--die", "2,2"], "--die needs three sides in cm, X,Y,Z"),
    (["--die", "2,2,-1"], "--die needs three sides > 0 cm"),
    (["--die", "2,2,nan"], "--die needs three sides in cm"),
    (["--load", "0.3"], "--load needs W@X,Y,Z"),
    (["--load", "1.2@0,0,0"], "--load needs a share W of the mass in [0, 1)"),
    (["--load", "0.3@5,0,0"], "--load: preset 'physical': load_cm (5.0, 0.0, 0.0) lies outside the box"),
    (["--set", "half_extents_cm=1,1,0"], "--set: preset 'physical': half_extents_cm must be three finite numbers > 0"),
    (["--die", "2,2,3", "--set", "half_extents_cm=1,1,1"], "--die and --set half_extents_cm both give the die"),
    (["--preset", "seed", "--die", "2,2,3"], "--integrator: preset 'seed' is no uniform cube"),
])
def test_bad_shapes_and_loads_are_refused_in_one_line_naming_the_option(tmp_path, dicetrace_cli, args, message):
    base = ["--preset", "physical", "--window", "home", "--res", "2"]
    res = dicetrace_cli("scan", *base, *args, "--out", str(tmp_path / "out"), cwd=tmp_path)
    assert res.returncode == 2 and res.stdout == "" and res.stderr.count("\n") == 1, res.stderr
    assert res.stderr.startswith("dicetrace: error: " + message), res.stderr
    assert not (tmp_path / "out").exists()


@pytest.mark.long
def test_a_loaded_die_scans_on_dask_as_here(tmp_path):
    pytest.importorskip("distributed")
    cfg = make_config("physical", load_fraction=0.3, load_cm=(-0.9, 0.0, 0.0))
    grid = Grid("seed", "home", (3, 3))
    here = scan(grid, tmp_path / "here", config=cfg, chunk=4)
    there = scan(grid, tmp_path / "dask", config=cfg, chunk=4, dask=True, n_workers=1)
    assert here.complete and there.complete
    assert read_scan_table(tmp_path / "dask").equals(read_scan_table(tmp_path / "here"))
    assert scan_definition(tmp_path / "dask").config.preset.load_fraction == 0.3
    assert os.path.exists(tmp_path / "dask" / "_scan.parquet")
