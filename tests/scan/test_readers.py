"""A scan folder's rolls table read as it is by Polars, pandas, DuckDB and pyarrow.dataset, and old layouts."""

from __future__ import annotations

import os
import shutil

import duckdb
import numpy as np
import pandas as pd
import polars as pl
import pyarrow.dataset as pads
import pytest

from dicetrace.ics import Grid
from dicetrace.scan import read_scan, scan
from dicetrace.scan.folder import CHUNK_LOG, MANIFEST, ROLLS_DIR, read_chunk_log, rolls_dir

GRID = Grid("seed", "home", 7)  # 49 ICs
COLUMNS = ["ic_id", "i", "j", "x", "y", "outcome", "status", "steps", "contact_sequence"]


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """A real scan folder of four chunks, with a chunk in flight (its hidden temporary beside the manifest)."""
    out = tmp_path_factory.mktemp("readers") / "home"
    scan(GRID, out, chunk=13)
    (out / ".part-000009.parquet.4242-running.tmp").write_bytes(b"PAR1 half written")
    return out


@pytest.fixture(scope="module")
def want(folder) -> pd.DataFrame:
    df = read_scan(folder, columns=COLUMNS)
    assert len(df) == 49 and (df["ic_id"] == np.arange(49)).all()
    return df


def _same(got: pd.DataFrame, want: pd.DataFrame) -> None:
    got = got[COLUMNS].sort_values("ic_id").reset_index(drop=True)
    for c in COLUMNS:
        g = got[c].astype(str) if c in ("status", "contact_sequence") else got[c]
        w = want[c].astype(str) if c in ("status", "contact_sequence") else want[c]
        assert list(g) == list(w), c


def test_the_rolls_folder_holds_the_finished_parts_and_nothing_else(folder):
    names = sorted(os.listdir(rolls_dir(folder)))
    assert names == [f"part-{c:06d}.parquet" for c in range(4)]
    assert sorted(os.listdir(folder)) == sorted(
        [".dicetrace-scan.lock", ".part-000009.parquet.4242-running.tmp", CHUNK_LOG, MANIFEST, ROLLS_DIR]
    )
    assert {e["file"] for e in read_chunk_log(folder).values()} == {f"rolls/{n}" for n in names}


def test_polars_reads_it(folder, want):
    _same(pl.scan_parquet(f"{folder}/rolls/").collect().to_pandas(), want)
    _same(pl.read_parquet(rolls_dir(folder)).to_pandas(), want)
    _same(pl.scan_parquet(f"{folder}/**/*.parquet").collect().to_pandas(), want)  # the glob polars suggests


def test_pandas_reads_it(folder, want):
    _same(pd.read_parquet(rolls_dir(folder)), want)
    _same(pd.read_parquet(folder), want)  # the scan folder itself: names starting with _ or . are skipped


def test_duckdb_reads_it(folder, want):
    for source in (f"{folder}/rolls/*.parquet", f"{folder}/rolls", f"{folder}/**/*.parquet"):
        _same(duckdb.sql(f"select * from read_parquet('{source}')").df(), want)
    n = duckdb.sql(f"select count(*) from '{folder}/rolls/*.parquet' where outcome between 1 and 6").fetchall()[0][0]
    assert n == int(want["outcome"].between(1, 6).sum())


def test_pyarrow_dataset_reads_it(folder, want):
    for source in (rolls_dir(folder), folder):
        _same(pads.dataset(source, format="parquet").to_table().to_pandas(), want)
    _same(pads.dataset(rolls_dir(folder)).to_table().to_pandas(), want)  # format guessed: parquet is the default


def test_a_folder_of_the_old_layout_is_read_and_moved_on_resume(tmp_path, folder, want):
    """Parts beside the manifest (dicetrace before rolls/): read as they are; the next scan moves them."""
    old = tmp_path / "old"
    shutil.copytree(folder, old)
    for p in sorted((old / ROLLS_DIR).iterdir()):
        p.rename(old / p.name)
    (old / ROLLS_DIR).rmdir()
    _same(read_scan(old), want)
    r = scan(GRID, old, chunk=13)
    assert (r.chunks_skipped, r.chunks_computed) == (4, 0)  # verified against the logged checksums, kept
    assert not list(old.glob("part-*")) and len(list((old / ROLLS_DIR).glob("part-*.parquet"))) == 4
    _same(pl.scan_parquet(f"{old}/rolls/").collect().to_pandas(), want)


def test_a_file_named_rolls_is_refused_not_overwritten(tmp_path):
    out = tmp_path / "s"
    scan(GRID, out, chunk=13, max_chunks=1)
    shutil.rmtree(out / ROLLS_DIR)
    (out / ROLLS_DIR).write_text("mine")
    with pytest.raises(FileExistsError, match="rolls.*is not a folder"):
        scan(GRID, out, chunk=13)
    assert (out / ROLLS_DIR).read_text() == "mine"


def test_the_scan_command_names_the_table_folder(tmp_path, dicetrace_cli):
    res = dicetrace_cli("scan", "--window", "home", "--res", "4", "--out", "s", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert f"→ s (the table: {os.path.join('s', 'rolls')}/)" in res.stderr
    assert len(pl.scan_parquet(tmp_path / "s" / "rolls").collect()) == 16
