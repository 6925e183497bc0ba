"""The three tables of ``record --parquet``: each read on its own by pandas, Polars, DuckDB and pyarrow; never mixed."""

from __future__ import annotations

import duckdb
import pandas as pd
import polars as pl
import pyarrow.dataset as pads
import pyarrow.parquet as pq
import pytest

from dicetrace.ics import seed_slice
from dicetrace.simulate import Record, simulate
from dicetrace.sinks import parquet as sink
from dicetrace.sinks._common import OutputError

TABLES = ("rolls", "contacts", "trajectory")


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    d = tmp_path_factory.mktemp("out")
    roll = simulate(seed_slice(1.65, 3.9), record=Record(states=True, energy=True))
    sink.write_tables(d, roll, coords=[[1.65, 3.9]], ic_ids=[7])
    return d


@pytest.fixture(scope="module")
def want(folder) -> dict[str, pd.DataFrame]:
    out = {t: pq.read_table(folder / f"{t}.parquet").to_pandas() for t in TABLES}
    assert [len(out[t]) for t in TABLES] == [1, 25, 541]  # the red-sea throw: 25 contact events, 540 steps
    return out


def _same(got: pd.DataFrame, want: pd.DataFrame) -> None:
    assert list(got.columns) == list(want.columns)
    assert len(got) == len(want)
    for c in ("ic_id", "t_s", "steps", "outcome", "node", "e_total"):
        if c in want:
            assert got[c].tolist() == want[c].tolist(), c


@pytest.mark.parametrize("table", TABLES)
def test_every_reader_reads_each_table(folder, want, table):
    f = folder / f"{table}.parquet"
    _same(pd.read_parquet(f), want[table])
    _same(pl.read_parquet(f).to_pandas(), want[table])
    _same(pl.scan_parquet(f).collect().to_pandas(), want[table])
    _same(duckdb.sql(f"select * from '{f}'").df(), want[table])
    _same(pads.dataset(f).to_table().to_pandas(), want[table])


def test_no_reader_mixes_the_tables_of_the_folder(folder):
    note = sink.NOTE_NAME
    with pytest.raises(Exception, match=note):
        pd.read_parquet(folder)
    with pytest.raises(Exception, match=note):
        pads.dataset(folder, format="parquet")
    with pytest.raises(Exception, match=note):
        pl.scan_parquet(folder).collect()
    with pytest.raises(Exception, match="extra column|schema"):
        pl.scan_parquet(f"{folder}/*.parquet").collect()
    with pytest.raises(Exception, match="schema mismatch"):
        duckdb.sql(f"select * from read_parquet('{folder}/*.parquet')").fetchall()


def test_the_note_says_how_to_read_each_table(folder):
    text = (folder / sink.NOTE_NAME).read_text()
    assert 'pd.read_parquet("FOLDER/rolls.parquet")' in text and "select * from 'FOLDER/rolls.parquet'" in text
    assert all(f"{t}.parquet" in text for t in TABLES)


def test_a_folder_where_the_note_goes_is_refused_and_nothing_is_written(tmp_path):
    (tmp_path / sink.NOTE_NAME).mkdir()
    roll = simulate(seed_slice(1.65, 3.9), t_max_s=0.1)
    with pytest.raises(OutputError, match=sink.NOTE_NAME):
        sink.write_tables(tmp_path, roll)
    assert [p.name for p in tmp_path.iterdir()] == [sink.NOTE_NAME]
