"""Scans: acceptance against `simulate`, invariance, resume, refusal, Dask, reading back, CLI."""

from __future__ import annotations

import csv
import io
import json
import signal
import subprocess
import sys
import time

import numpy as np
import pandas as pd
import pyarrow as pa
import pytest

from dicetrace.ics import Grid, Points, Sample, seed_slice
from dicetrace.scan import (
    MISSING,
    ScanDefinition,
    ScanMismatchError,
    grid_axes,
    ic_at,
    label_grid,
    read_manifest,
    read_scan,
    scan,
)
from dicetrace.simulate import simulate
from scan_rows import rows as _data

HOME21 = Grid("seed", "home", 21)


def cli(*args: str, cwd=None, timeout=300) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "dicetrace.cli", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=timeout)


@pytest.fixture(scope="module")
def home21() -> pa.Table:
    return scan(HOME21, chunk=100)


# -- acceptance -------------------------------------------------------------------------------


def test_home_grid_matches_simulate_point_for_point(home21):
    df = home21.to_pandas()
    assert len(df) == 441 and (df["ic_id"] == np.arange(441)).all()
    xs, ys = HOME21.axes()
    for r in df.itertuples():
        assert (r.x, r.y) == (xs[r.i], ys[r.j]) and r.k == 0 and np.isnan(r.z)
        roll = simulate(seed_slice(r.x, r.y), preset="seed")
        assert (r.outcome, r.steps, r.status, r.contact_sequence) == (
            roll.outcome, roll.steps, roll.status, roll.contact_sequence)
        np.testing.assert_array_equal(r.contact_sets, roll.contact_sets)
        assert r.n_contact_changes == len(roll.contact_sets) - 1
        assert r.t_settle_s == roll.t_settle_s
        np.testing.assert_array_equal([r.vx, r.vy, r.vz, r.Lx, r.Ly, r.Lz], roll.ic)
    assert set(df["preset"]) == {"seed"} and set(df["integrator"]) == {"semi-implicit-euler"}
    assert set(df["dt_s"]) == {0.001}


def test_cli_scan_matches_cli_simulate(tmp_path, home21, dicetrace_cli):
    """`dicetrace scan --slice seed --window home --res 21` = `dicetrace simulate` on the same ICs."""
    res = dicetrace_cli("scan", "--slice", "seed", "--window", "home", "--res", "21", "--out", str(tmp_path / "home"), "-q",
                        cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    df = read_scan(tmp_path / "home")
    assert _data(df).select(["ic_id", "outcome", "steps"]).equals(
        _data(home21).select(["ic_id", "outcome", "steps"]))
    pts = tmp_path / "pts.csv"
    df[["x", "y"]].to_csv(pts, index=False, float_format="%.17g")
    sim = dicetrace_cli("simulate", "--slice", "seed", "--ics", str(pts), "--format", "csv", cwd=tmp_path)
    assert sim.returncode == 0, sim.stderr
    rows = list(csv.DictReader(io.StringIO(sim.stdout)))
    assert len(rows) == 441
    for r, s in zip(df.itertuples(), rows):
        assert (str(r.outcome), str(r.steps), r.status, r.contact_sequence) == (
            s["outcome"], s["steps"], s["status"], s["contact_sequence"])


def test_numeric_window_equals_named_window(tmp_path, home21, dicetrace_cli):
    res = dicetrace_cli("scan", "--window", "0,0.1,0,0.1", "--res", "21", "--out", str(tmp_path / "w"), "--chunk", "100", "-q",
                        cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert _data(read_scan(tmp_path / "w")).equals(
        _data(home21))


def test_writeup_points_through_a_scan(reference_dir):
    ref = pd.read_csv(reference_dir / "writeup_points.csv")
    t = scan(Points("seed", ref[["x", "y"]].to_numpy())).to_pandas()
    assert t["outcome"].tolist() == ref["outcome"].tolist()
    assert t["steps"].tolist() == ref["steps"].tolist()
    assert t["contact_sequence"].tolist() == ref["contact_sequence"].tolist()
    assert (t[["i", "j", "k"]] == -1).all().all()
    # points 1-3 also lie on the red-sea grid at 21×21
    g = scan(Grid("seed", "red-sea", 21), chunk=500).to_pandas().set_index(["x", "y"])
    for r in ref.iloc[:3].itertuples():
        row = g.loc[(r.x, r.y)]
        assert (row.outcome, row.steps, row.contact_sequence) == (r.outcome, r.steps, r.contact_sequence)


# -- invariance --------------------------------------------------------------------------------


@pytest.mark.parametrize("threads, chunk", [(1, 441), (2, 441), (1, 7), (2, 64), (2, 1000)])
def test_thread_count_and_chunk_size_invariance(home21, threads, chunk):
    t = scan(HOME21, chunk=chunk, threads=threads)
    assert _data(t).equals(_data(home21))


# -- folders: resume, refusal ---------------------------------------------------------------------


def test_resume_after_interruption(tmp_path, home21):
    out = tmp_path / "scan"
    r1 = scan(HOME21, out, chunk=50, max_chunks=3)
    assert (r1.chunks_computed, r1.complete) == (3, False)
    # a write killed half way leaves only a hidden temporary file
    (out / ".part-000004.parquet.999-dead.tmp").write_bytes(b"PAR1 half a file")
    partial = read_scan(out)
    assert len(partial) == 150
    assert (label_grid(out) == MISSING).sum() == 441 - 150
    r2 = scan(HOME21, out, chunk=50)
    assert (r2.chunks_skipped, r2.chunks_computed, r2.complete) == (3, 6, True)
    assert not list(out.glob(".*.tmp"))
    df = read_scan(out)
    assert (df["ic_id"] == np.arange(441)).all()  # every IC exactly once
    assert _data(df).equals(
        _data(home21))
    r3 = scan(HOME21, out, chunk=50)
    assert (r3.chunks_skipped, r3.chunks_computed) == (9, 0)


@pytest.mark.slow
def test_resume_after_sigkill(tmp_path):
    out = tmp_path / "killed"
    args = ["scan", "--window", "0,1,0,1", "--res", "100", "--chunk", "250", "--threads", "1", "--out", str(out), "-q"]
    proc = subprocess.Popen([sys.executable, "-m", "dicetrace.cli", *args], stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE)
    t0 = time.time()
    while len(list(out.glob("rolls/part-*.parquet"))) < 2 and proc.poll() is None and time.time() - t0 < 120:
        time.sleep(0.01)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    n_before = len(list(out.glob("rolls/part-*.parquet")))
    assert 0 < n_before < 40, "the kill should land mid-scan"
    res = cli(*args)
    assert res.returncode == 0, res.stderr
    df = read_scan(out)
    assert (df["ic_id"] == np.arange(100 * 100)).all()
    want = scan(Grid("seed", ((0, 1), (0, 1)), 100), chunk=2500)
    assert _data(df).equals(_data(want))


def test_refuses_to_mix_definitions(tmp_path, dicetrace_cli):
    out = tmp_path / "s"
    scan(Grid("seed", "home", 5), out, chunk=10)
    with pytest.raises(ScanMismatchError, match="res"):
        scan(Grid("seed", "home", 6), out, chunk=10)
    with pytest.raises(ScanMismatchError, match="gamma"):
        scan(Grid("seed", "home", 5), out, chunk=10, gamma=0.01)
    with pytest.raises(ScanMismatchError, match="chunk"):
        scan(Grid("seed", "home", 5), out, chunk=11)
    with pytest.raises(ScanMismatchError, match="window"):
        scan(Grid("seed", "zoom-out", 5), out, chunk=10)
    assert len(read_scan(out)) == 25  # untouched
    res = dicetrace_cli("scan", "--window", "party", "--res", "5", "--out", str(out), cwd=tmp_path)
    assert res.returncode == 2
    assert "holds a different scan" in res.stderr and "Traceback" not in res.stderr
    other = tmp_path / "notascan"
    other.mkdir()
    (other / "notes.txt").write_text("mine")
    with pytest.raises(FileExistsError):
        scan(Grid("seed", "home", 5), other)


# -- Dask --------------------------------------------------------------------------------------------


@pytest.mark.slow
def test_dask_local_cluster_equals_local_run(tmp_path, home21):
    pytest.importorskip("dask.distributed")
    from dask.distributed import Client, LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0") as cluster:
        with Client(cluster) as client:
            t = scan(HOME21, chunk=100, dask=client)
            assert _data(t).equals(_data(home21))
            r = scan(HOME21, tmp_path / "d", chunk=100, dask=client)
            assert r.complete
        # --scheduler ADDRESS: scan opens (and closes) a client of its own
        by_address = scan(HOME21, chunk=150, dask=cluster.scheduler_address)
        assert _data(by_address).equals(_data(home21))
    df = read_scan(tmp_path / "d")
    assert _data(df).equals(
        _data(home21))


# -- reading back ---------------------------------------------------------------------------------------


def test_label_grid_and_axes(tmp_path, home21):
    out = tmp_path / "g"
    scan(HOME21, out, chunk=200)
    g = label_grid(out)
    assert g.shape == (21, 21) and g.dtype == np.int8
    xs, ys = grid_axes(out)
    df = read_scan(out)
    for r in df.sample(40, random_state=1).itertuples():
        assert g[r.i, r.j] == r.outcome and xs[r.i] == r.x and ys[r.j] == r.y
    np.testing.assert_array_equal(label_grid(df), g)
    seqs = label_grid(out, "contact_sequence")
    assert seqs.shape == (21, 21) and seqs[3, 4] == df.loc[3 * 21 + 4, "contact_sequence"]
    steps = label_grid(df, "steps")
    assert steps.dtype == np.int64 and steps[20, 20] == df["steps"].iloc[-1]


def test_three_d_grid(tmp_path):
    grid = Grid("seed3", ((0, 0.1), (0, 0.1), (0, 0.05)), (4, 3, 2))
    out = tmp_path / "cube"
    scan(grid, out, chunk=5)
    g = label_grid(out)
    assert g.shape == (4, 3, 2)
    df = read_scan(out)
    xs, ys, zs = grid_axes(out)
    r = df.iloc[13]
    assert (r.i, r.j, r.k) == np.unravel_index(13, (4, 3, 2))
    roll = simulate(seed_slice(xs[r.i], ys[r.j], zs[r.k]))
    assert (g[r.i, r.j, r.k], r.steps, r.contact_sequence) == (roll.outcome, roll.steps, roll.contact_sequence)


def test_ic_at_reproduces_the_row_exactly(tmp_path):
    out = tmp_path / "rs"
    scan(Grid("seed", "red-sea", 21), out, chunk=200)
    ic, cfg, row = ic_at(out, (1.65, 3.9))
    assert (row["x"], row["y"]) == (1.65, 3.9)
    roll = simulate(ic, config=cfg)
    assert (roll.outcome, roll.steps, roll.contact_sequence) == (row["outcome"], row["steps"], row["contact_sequence"])
    ic2, _, row2 = ic_at(out, (1.652, 3.898))  # nearest node
    assert (row2["x"], row2["y"]) == (1.65, 3.9)
    with pytest.raises(ValueError, match="no scanned IC near"):
        ic_at(out, (5.0, 5.0))


def test_physical_preset_gets_physical_L(tmp_path):
    t = scan(Grid("seed", "home", 3), preset="physical").to_pandas()
    ics = seed_slice(t["x"].to_numpy(), t["y"].to_numpy())
    np.testing.assert_array_equal(t[["Lx", "Ly", "Lz"]].to_numpy(), -ics[:, 3:])
    for r in t.itertuples():
        roll = simulate([r.vx, r.vy, r.vz, r.Lx, r.Ly, r.Lz], preset="physical")
        assert (roll.outcome, roll.steps, roll.contact_sequence) == (r.outcome, r.steps, r.contact_sequence)


def test_sample_scan(tmp_path):
    s = Sample("seed", ((0, 20), (0, 20)), 300, "sobol", seed=2)
    out = tmp_path / "sobol"
    scan(s, out, chunk=128)
    df = read_scan(out)
    assert (df["ic_id"] == np.arange(300)).all() and (df[["i", "j", "k"]] == -1).all().all()
    coords = s.block(0, 300).coords
    np.testing.assert_array_equal(df[["x", "y"]].to_numpy(), coords[:, :2])
    with pytest.raises(ValueError, match="not a grid"):
        label_grid(out)


def test_metadata_and_manifest(tmp_path):
    import pyarrow.parquet as pq

    import dicetrace

    out = tmp_path / "m"
    scan(Grid("seed", "home", 4), out, chunk=10, gamma=0.01)
    man = read_manifest(out)
    assert man["dicetrace_version"] == dicetrace.__version__ and man["n_ics"] == 16 and man["n_chunks"] == 2
    defn = ScanDefinition.from_dict(man["definition"])
    assert defn.config.preset.gamma == 0.01 and defn.space == Grid("seed", "home", 4)
    meta = json.loads(pq.read_schema(out / "rolls" / "part-000001.parquet").metadata[b"dicetrace"])
    assert meta["scan"] == man["definition"] and meta["ic_range"] == [10, 16]
    assert meta["dicetrace_version"] == dicetrace.__version__
    assert len(pd.read_parquet(out)) == 16  # a plain Parquet dataset


@pytest.mark.slow  # about a second
def test_png_and_rrd(tmp_path):
    from rerun.chunk import RrdReader

    from dicetrace.scan.map_rrd import write_scan_rrd
    from dicetrace.scan.maps import outcome_png

    out, png, rrd = tmp_path / "s", tmp_path / "map.png", tmp_path / "map.rrd"
    scan(Grid("seed", "party", 9), out)
    outcome_png(out, png)
    write_scan_rrd(out, rrd)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # the map shows each outcome of the grid in its colour, in proportion to its cells, and no other outcome
    import matplotlib.image

    from dicetrace.scan.colours import OUTCOME_RGB

    img = np.round(matplotlib.image.imread(png)[..., :3] * 255).astype(int)
    grid = label_grid(out)
    colored = [1, 2, 3, 4, 5]  # white (-1), grey (0) and black (6) are also the figure's paper, text and axes
    pixels = {o: int((img == np.array(OUTCOME_RGB[o])).all(axis=-1).sum()) for o in colored}
    cells = {o: int((grid == o).sum()) for o in colored}
    assert {o for o, n in pixels.items() if n} == {o for o, n in cells.items() if n}
    assert sum(1 for n in cells.values() if n) > 1
    for o in colored:
        assert pixels[o] / sum(pixels.values()) == pytest.approx(cells[o] / sum(cells.values()), abs=0.02), o
    df = read_scan(out)
    n = 0
    for ch in RrdReader(str(rrd)).stream():
        if ch.entity_path == "/map/cells":  # the hover points (the rest of the map: tests/scan/test_map_rrd.py)
            batch = ch.to_record_batch()
            n = len(batch.column(batch.schema.names.index("Points2D:positions"))[0])
            label = str(batch.column(batch.schema.names.index("Points2D:labels"))[0][0])
            r = df.iloc[0]
            # rounded to the grid's resolution: cells 0.00075 by 0.00125 wide
            assert label == f"x={r['x']:.5f}, y={r['y']:.4f}: face {r['outcome']}, {r['steps']} steps"
    assert n == 81


def bad(args, *names, gap=None):
    """A bad ``dicetrace scan`` input; ``names`` must all be in the error line, the offending option or path first.

    ``gap``: what the message (or the command) does not do yet: a strict xfail,
    which fails once it is fixed, so that the mark is then removed.
    """
    marks = [pytest.mark.xfail(strict=True, reason=gap)] if gap else []
    return pytest.param(args, names, id=" ".join(args), marks=marks)


def test_a_definition_naming_a_removed_integrator_is_refused_in_one_line():
    """A scan written with contact-rosenbrock (removed) reads as a definition no more: one line that says so."""
    from dicetrace.params import make_config

    d = ScanDefinition(Grid("seed", "home", 4), make_config("physical", integrator="contact-tsit5"), 10).to_dict()
    d = json.loads(json.dumps(d).replace('"contact-tsit5"', '"contact-rosenbrock"'))
    with pytest.raises(ValueError) as exc:
        ScanDefinition.from_dict(d)
    (line,) = str(exc.value).splitlines()
    assert "'contact-rosenbrock'" in line and "removed" in line


HOME5 = ["--window", "home", "--res", "5"]
SCAN_BAD = [
    bad(["--window", "atlantis", "--res", "5"], "--window", "unknown window 'atlantis'"),
    bad(["--window", "0,1,0", "--res", "5"], "--window", "'0,1,0'"),
    bad(["--window", "home"], "--res", "--window needs"),
    bad(["--res", "5"], "--window", "--sample", "--points"),
    bad(["--slice", "seed3", "--window", "home", "--res", "5"], "--z", "z range"),
    bad(["--slice", "seed3", "--window", "home", "--z", "0", "--res", "5"], "--z", "'0'"),
    bad(["--slice", "nope", *HOME5], "--slice", "unknown slice 'nope'"),
    bad(["--window", "home", "--res", "5,5,5"], "--res", "needs 2"),
    bad(["--window", "home", "--res", "0"], "--res", ">= 1"),
    bad(["--window", "home", "--res", "a"], "--res", "'a'"),
    bad(["--sample", "sobol", "--box", "home"], "--n", "--sample needs"),
    bad(["--sample", "sobol", "--n", "5"], "--box", "--sample needs"),
    bad(["--sample", "halton", "--n", "5", "--box", "home"], "--sample", "'halton'"),
    bad(["--sample", "sobol", "--n", "0", "--box", "home"], "--n", ">= 1"),
    bad(["--sample", "sobol", "--n", "5", "--box", "home", "--png", "x.png"], "--png", "grid"),
    bad(["--points", "missing.csv"], "--points", "'missing.csv'"),
    bad(["--origin", "1,2,3", "--dir", "1,0,0,0,0,0", "--window", "0,1", "--res", "5"], "--origin", "6 comma-separated"),
    bad(["--origin", "0,0,0,0,0,0", "--window", "0,1", "--res", "5"], "--dir", "--origin"),
    bad(["--origin", "0,0,0,0,0,0", "--dir", "0,0,0,0,0,0", "--window", "0,1", "--res", "5"], "--dir", "linearly dependent"),
    bad([*HOME5, "--dask", "--scheduler", "tcp://x:1"], "--dask", "--scheduler", "not both"),
    bad([*HOME5, "--set", "gama=0.01"], "--set", "'gama=0.01'"),
    bad([*HOME5, "--set", "gamma=abc"], "--set", "'abc'"),
    bad([*HOME5, "--set", "clamp_normal=maybe"], "--set", "'maybe'"),
    bad([*HOME5, "--set", "k=-1"], "--set", "k must be > 0"),
    bad([*HOME5, "--preset", "moon"], "--preset", "'moon'"),
    bad([*HOME5, "--integrator", "magic"], "--integrator", "'magic'"),
    bad([*HOME5, "--integrator", "contact-rosenbrock"], "--integrator", "'contact-rosenbrock'", "removed"),
    bad([*HOME5, "--dt", "0"], "--dt", "'0'"),
    bad([*HOME5, "--t-max", "x"], "--t-max", "'x'"),
    bad([*HOME5, "--integrator", "contact-adaptive", "--tol", "5"], "--tol", "[1e-14, 1)"),
    bad([*HOME5, "--chunk", "0"], "--chunk", ">= 1"),
    bad([*HOME5, "--threads", "0"], "--threads", ">= 1"),
    bad([*HOME5, "--png", "{file}/map.png"], "--png", "{file}"),
    bad([*HOME5, "--rrd", "{file}/map.rrd"], "--rrd", "{file}"),
    bad([*HOME5, "--events"], "--events", "'semi-implicit-euler'", "no exact contact events"),
]


@pytest.mark.parametrize("args, names", SCAN_BAD)
def test_cli_bad_input(tmp_path, args, names, capsys, monkeypatch):
    """One line on stderr naming the option, exit code 2, no traceback, no scan folder (in-process: the console
    script's run_app)."""
    from dicetrace.cli import app
    from dicetrace.commands._common import run_app

    afile = tmp_path / "afile"
    afile.write_text("not a folder")
    args = [a.replace("{file}", str(afile)) for a in args]
    names = [n.replace("{file}", str(afile)) for n in names]
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "argv", ["dicetrace", "scan", *args, "--out", str(tmp_path / "x"), "-q"])
    with pytest.raises(SystemExit) as exc:
        run_app(app)
    out, err = capsys.readouterr()
    assert exc.value.code == 2 and out == "" and "Traceback" not in err
    assert not (tmp_path / "x").exists()  # refused before any work
    (line,) = err.strip().splitlines()
    assert line.startswith("dicetrace: error: ")
    missing = [n for n in names if n not in line]
    assert not missing, f"the message does not name {missing}: {line}"


def test_cli_out_is_a_file(tmp_path, capsys, monkeypatch):
    from dicetrace.cli import app
    from dicetrace.commands._common import run_app

    out = tmp_path / "afile"
    out.write_text("mine")
    monkeypatch.setattr(sys, "argv", ["dicetrace", "scan", *HOME5, "--out", str(out), "-q"])
    with pytest.raises(SystemExit) as exc:
        run_app(app)
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert exc.value.code == 2 and line.startswith(f"dicetrace: error: --out {str(out)!r}")
    assert out.read_text() == "mine"


def test_a_single_z_plane_is_a_grid_axis_of_one_point(tmp_path, dicetrace_cli):
    """The one window rule: x1 > x0 on every axis, except a grid axis of one point (that point is z0)."""
    res = dicetrace_cli("scan", "--slice", "seed3", "--window", "home", "--z", "0.02,0.02", "--res", "3,3,1",
                        "--out", "s", "-q", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    df = read_scan(tmp_path / "s")
    assert len(df) == 9 and (df["z"] == 0.02).all()


def test_a_zero_width_window_or_box_is_refused_by_the_api_too():
    from dicetrace.ics import Sample, get_window

    with pytest.raises(ValueError, match=r"x1 > x0 \(zero width\)"):
        Grid("seed", ((1.0, 1.0), (0.0, 1.0)), 10)
    with pytest.raises(ValueError, match=r"y1 > y0 \(negative width\)"):
        Grid("seed", ((0.0, 1.0), (1.0, 0.0)), (3, 1))  # one point on y: still not inverted
    with pytest.raises(ValueError, match="zero width"):
        Sample("seed", ((1.0, 1.0), (0.0, 1.0)), 10)
    with pytest.raises(ValueError, match="zero width"):
        get_window("1,1,0,1")
    assert Grid("seed", ((1.0, 1.0), (0.0, 1.0)), (1, 10)).size == 10


def test_a_whole_table_in_memory_that_would_not_fit_is_refused_before_any_work():
    with pytest.raises(ValueError, match=r"out: the rolls table of 10,000,000,000 ICs .* give out="):
        scan(Grid("seed", "home", 10**5))

