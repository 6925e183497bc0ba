"""A scan folder read as it is -- the folder itself, and its rolls/ -- by Polars, pandas, DuckDB and
pyarrow.dataset, with the manifest's metadata readable without dicetrace; and the layouts of older versions."""

from __future__ import annotations

import json
import os
import shutil

import duckdb
import numpy as np
import pandas as pd
import polars as pl
import pyarrow.dataset as pads
import pyarrow.parquet as pq
import pytest

from dicetrace.ics import Grid
from dicetrace.scan import read_scan, scan
from dicetrace.scan.folder import (
    CHUNK_LOG_KEY,
    LEGACY_CHUNK_LOG,
    LEGACY_MANIFEST,
    LOCK,
    MANIFEST,
    MANIFEST_KEY,
    ROLLS_DIR,
    read_chunk_log,
    read_manifest,
    rolls_dir,
)

GRID = Grid("seed", "home", 7)  # 49 ICs
COLUMNS = ["ic_id", "i", "j", "x", "y", "outcome", "status", "steps", "contact_sequence"]


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """A real, finished scan folder of four chunks."""
    out = tmp_path_factory.mktemp("readers") / "home"
    scan(GRID, out, chunk=13)
    return out


@pytest.fixture
def writing(folder, tmp_path):
    """A copy of ``folder`` with a chunk in flight: its hidden temporary beside the manifest, as a scan leaves it."""
    out = tmp_path / "writing"
    shutil.copytree(folder, out)
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


def test_the_folder_holds_parquet_files_of_one_schema_and_the_empty_lock(folder):
    """What lets Polars read the folder: it reads every non-empty file under it, and refuses two extensions."""
    names = sorted(os.listdir(rolls_dir(folder)))
    assert names == [f"part-{c:06d}.parquet" for c in range(4)]
    assert sorted(os.listdir(folder)) == sorted([LOCK, MANIFEST, ROLLS_DIR])
    assert (folder / LOCK).stat().st_size == 0
    manifest = pq.read_table(folder / MANIFEST)
    assert manifest.num_rows == 0 and manifest.schema.equals(pq.read_schema(rolls_dir(folder) / names[0]))
    assert {e["file"] for e in read_chunk_log(folder).values()} == {f"rolls/{n}" for n in names}


def test_the_manifest_is_read_without_dicetrace(folder):
    meta = pq.read_schema(folder / MANIFEST).metadata
    assert json.loads(meta[MANIFEST_KEY]) == read_manifest(folder)
    assert json.loads(meta[MANIFEST_KEY])["definition"]["space"]["res"] == [7, 7]
    assert sorted(json.loads(meta[CHUNK_LOG_KEY])) == ["0", "1", "2", "3"]
    kv = duckdb.sql(f"select key, value from parquet_kv_metadata('{folder}/{MANIFEST}')").fetchall()
    assert {bytes(k) for k, _ in kv} >= {MANIFEST_KEY, CHUNK_LOG_KEY}


def test_polars_reads_it(folder, want):
    _same(pl.scan_parquet(f"{folder}/").collect().to_pandas(), want)  # the scan folder itself, as it is
    _same(pl.read_parquet(folder).to_pandas(), want)
    _same(pl.scan_parquet(f"{folder}/rolls/").collect().to_pandas(), want)
    _same(pl.scan_parquet(f"{folder}/**/*.parquet").collect().to_pandas(), want)


def test_pandas_reads_it(folder, want):
    _same(pd.read_parquet(folder), want)  # the scan folder itself: names starting with _ or . are skipped
    _same(pd.read_parquet(rolls_dir(folder)), want)


def test_duckdb_reads_it(folder, want):
    for source in (f"{folder}/**/*.parquet", str(folder), f"{folder}/rolls/*.parquet", f"{folder}/rolls"):
        _same(duckdb.sql(f"select * from read_parquet('{source}')").df(), want)
    n = duckdb.sql(f"select count(*) from '{folder}/**/*.parquet' where outcome between 1 and 6").fetchall()[0][0]
    assert n == int(want["outcome"].between(1, 6).sum())


def test_pyarrow_dataset_reads_it(folder, want):
    for source in (folder, rolls_dir(folder)):
        _same(pads.dataset(source, format="parquet").to_table().to_pandas(), want)
    _same(pads.dataset(folder).to_table().to_pandas(), want)  # format guessed: parquet is the default


def test_while_a_scan_writes_rolls_is_read_by_all_and_the_folder_by_all_but_polars(writing, want):
    """A chunk in flight lies beside the manifest under a hidden temporary name: Polars, which reads every file,
    refuses the folder then (as the docs say); rolls/ holds finished parts only."""
    _same(pl.scan_parquet(f"{writing}/rolls/").collect().to_pandas(), want)
    _same(pd.read_parquet(writing), want)
    _same(pads.dataset(writing, format="parquet").to_table().to_pandas(), want)
    _same(duckdb.sql(f"select * from read_parquet('{writing}/**/*.parquet')").df(), want)
    with pytest.raises(pl.exceptions.InvalidOperationError, match="different file extensions"):
        pl.scan_parquet(f"{writing}/").collect()


@pytest.mark.parametrize("parts_beside", [True, False], ids=["parts-beside-the-manifest", "rolls"])
def test_a_folder_of_an_older_layout_is_read_and_converted_on_resume(tmp_path, folder, want, to_legacy_layout,
                                                                     parts_beside):
    """``_scan.json`` and ``_scan.chunks.jsonl`` (dicetrace before the Parquet manifest), the parts beside them (before rolls/) or
    in rolls/: read as they are; the next scan keeps the verified chunks and writes this version's layout."""
    old = tmp_path / "old"
    shutil.copytree(folder, old)
    to_legacy_layout(old, parts_beside=parts_beside)
    assert not (old / MANIFEST).exists() and (old / LEGACY_CHUNK_LOG).exists()
    _same(read_scan(old), want)
    assert read_manifest(old)["definition"] == read_manifest(folder)["definition"]
    r = scan(GRID, old, chunk=13)
    assert (r.chunks_skipped, r.chunks_computed) == (4, 0)  # verified against the logged checksums, kept
    assert sorted(os.listdir(old)) == sorted([LOCK, MANIFEST, ROLLS_DIR])
    assert not (old / LEGACY_MANIFEST).exists()
    assert sorted(read_chunk_log(old)) == [0, 1, 2, 3]
    _same(pl.scan_parquet(f"{old}/").collect().to_pandas(), want)


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
    assert "→ s (a Parquet dataset: read the folder as it is)" in res.stderr
    assert len(pl.scan_parquet(tmp_path / "s").collect()) == 16


def test_read_manifest_of_a_file_says_it_is_a_file(folder, tmp_path):
    """Given a file -- any, or the manifest itself -- read_manifest says so (a FileNotFoundError once, for a file
    that exists); a path that holds no scan is still FileNotFoundError."""
    with pytest.raises(NotADirectoryError, match=r"_scan\.parquet' is a file, not a dicetrace scan folder: give its "
                                                 r"folder, '.*home'"):
        read_manifest(folder / MANIFEST)
    (tmp_path / "notes.txt").write_text("mine")
    with pytest.raises(NotADirectoryError, match=r"notes\.txt' is a file"):
        read_manifest(tmp_path / "notes.txt")
    with pytest.raises(FileNotFoundError, match="no _scan.parquet"):
        read_manifest(tmp_path / "nowhere")
    assert read_manifest(folder)["n_ics"] == 49
