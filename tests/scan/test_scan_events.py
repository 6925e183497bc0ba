"""Scans with exact contact events (``scan(..., events=True)``, ``dicetrace scan --events``): the rows of
``simulate_batch(..., events=True)`` in a Parquet dataset with a ``contact_times_s`` column, resumable, refused
where the integrator or the device has no events."""

from __future__ import annotations

import json
import os

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

from dicetrace.ics import Grid
from dicetrace.params import ConfigError, make_config
from dicetrace.scan import ScanDefinition, ScanMismatchError, read_manifest, read_scan, scan
from dicetrace.scan.estimate import estimate_scan
from dicetrace.scan.folder import MANIFEST_KEY
from dicetrace.simulate import simulate_batch

GRID = Grid("seed", "home", 4)  # 16 ICs: 4 chunks of 4, the last ones' throws as the first ones'
PHYSICAL = make_config("physical")


@pytest.fixture(scope="module")
def events_scan(tmp_path_factory):
    folder = tmp_path_factory.mktemp("scan") / "ev"
    report = scan(GRID, folder, config=PHYSICAL, chunk=4, events=True)
    assert report.complete
    return folder


def test_an_events_scan_holds_simulate_batchs_events_bit_for_bit(events_scan):
    df = read_scan(events_scan)
    blk = GRID.block(0, GRID.size)
    want = simulate_batch(blk.ics, config=PHYSICAL, l_convention=GRID.slice.l_convention, events=True)
    plain = simulate_batch(blk.ics, config=PHYSICAL, l_convention=GRID.slice.l_convention)
    np.testing.assert_array_equal(df["ic_id"], np.arange(GRID.size))
    for i in range(GRID.size):
        a, b = want.set_offsets[i], want.set_offsets[i + 1]
        np.testing.assert_array_equal(df["contact_times_s"][i], want.set_times[a:b])
        np.testing.assert_array_equal(df["contact_sets"][i], want.sets[a:b])
        assert df["contact_times_s"][i][0] == 0.0 and np.all(np.diff(df["contact_times_s"][i]) > 0)
    # the throws are those of a scan without events: only the contact sets differ (the events see more)
    np.testing.assert_array_equal(df["outcome"], plain.outcome)
    np.testing.assert_array_equal(df["steps"], plain.steps)
    assert (df["n_contact_changes"] >= np.diff(plain.set_offsets) - 1).all()
    assert (df["n_contact_changes"] > np.diff(plain.set_offsets) - 1).any()


def test_any_parquet_reader_reads_the_folder_with_its_times(events_scan):
    """The manifest (no rows) carries the events schema: a plain reader of the whole folder unifies them."""
    assert "contact_times_s" in pq.read_schema(events_scan / "_scan.parquet").names
    df = pd.read_parquet(events_scan).sort_values("ic_id")
    assert len(df) == GRID.size
    np.testing.assert_array_equal(df["contact_times_s"].iloc[3], read_scan(events_scan)["contact_times_s"][3])
    assert read_manifest(events_scan)["definition"]["events"] is True
    times = read_scan(events_scan, columns=["contact_times_s"])
    assert list(times.columns) == ["ic_id", "contact_times_s"]


def test_a_scan_with_events_resumes_and_refuses_one_without(tmp_path, events_scan):
    folder = tmp_path / "ev"
    first = scan(GRID, folder, config=PHYSICAL, chunk=4, events=True, max_chunks=2)
    assert first.chunks_computed == 2
    report = scan(GRID, folder, config=PHYSICAL, chunk=4, events=True)
    assert (report.chunks_skipped, report.chunks_computed) == (2, 2)
    assert read_scan(folder).equals(read_scan(events_scan))
    with pytest.raises(ScanMismatchError, match="events: true vs false"):
        scan(GRID, folder, config=PHYSICAL, chunk=4)


def test_a_folder_from_before_events_resumes_as_a_scan_without_them(tmp_path):
    from dicetrace.scan.folder import _write_manifest, read_chunk_log

    folder = tmp_path / "s"
    scan(GRID, folder, config=PHYSICAL, chunk=4, max_chunks=2)
    manifest = read_manifest(folder)
    del manifest["definition"]["events"]
    _write_manifest(folder, manifest, read_chunk_log(folder))
    assert "events" not in json.loads(pq.read_schema(folder / "_scan.parquet").metadata[MANIFEST_KEY])["definition"]
    report = scan(GRID, folder, config=PHYSICAL, chunk=4)
    assert (report.chunks_skipped, report.chunks_computed) == (2, 2)
    assert "contact_times_s" not in read_scan(folder).columns
    with pytest.raises(ScanMismatchError, match="events"):
        scan(GRID, folder, config=PHYSICAL, chunk=4, events=True)


def test_events_are_refused_where_there_are_none(tmp_path):
    with pytest.raises(ConfigError, match="'semi-implicit-euler' has no exact contact events") as exc:
        scan(GRID, tmp_path / "a", chunk=4, events=True)
    assert exc.value.fields == ("events",)
    with pytest.raises(ConfigError, match="events must be True or False"):
        ScanDefinition(GRID, PHYSICAL, 4, events="yes")
    with pytest.raises(ValueError, match="not both"):
        scan(ScanDefinition(GRID, PHYSICAL, 4), events=True)
    assert not any(tmp_path.iterdir())


def test_a_definition_round_trips_its_events_and_reads_none_as_without():
    d = ScanDefinition(GRID, PHYSICAL, 4, events=True)
    assert ScanDefinition.from_dict(d.to_dict()) == d
    old = {k: v for k, v in d.to_dict().items() if k != "events"}
    assert ScanDefinition.from_dict(old).events is False
    assert d.schema.names[-1] == "contact_times_s" and "contact_times_s" not in ScanDefinition(GRID, PHYSICAL).schema.names


def test_an_events_definition_may_name_a_gpu_and_an_events_scan_records_its_device():
    d = ScanDefinition(GRID, PHYSICAL, 4, device="cuda: Some GPU", events=True)
    assert ScanDefinition.from_dict(d.to_dict()) == d
    t = scan(Grid("seed", "home", 2), config=PHYSICAL, events=True, device="auto")  # no GPU here: the CPU
    meta = json.loads(t.schema.metadata[b"dicetrace"])
    assert meta["device"] == "cpu" and meta["scan"]["events"] is True
    assert t.schema.names[-1] == "contact_times_s"


@pytest.mark.long
def test_the_disk_estimate_bounds_an_events_scan(tmp_path):
    """The estimate (before any work) is an upper bound of what the rows take on disk, with their times."""
    space = Grid("seed", "zoom-out", 48)
    defn = ScanDefinition(space, PHYSICAL, 1024, events=True)
    plain = ScanDefinition(space, PHYSICAL, 1024)
    est = estimate_scan(defn, calibrate=False)
    scan(defn, tmp_path / "ev")
    scan(plain, tmp_path / "plain")
    size = {name: sum(f.stat().st_size for f in (tmp_path / name / "rolls").iterdir()) for name in ("ev", "plain")}
    assert size["plain"] < size["ev"] <= est.bytes
    assert size["ev"] > estimate_scan(plain, calibrate=False).bytes  # a scan without events' estimate would not hold them
    assert est.chunk_memory > estimate_scan(plain, calibrate=False).chunk_memory


@pytest.mark.slow
def test_the_probe_counts_the_events_of_throws_that_never_settle_and_the_estimate_bounds_their_files(tmp_path,
                                                                                                   monkeypatch):
    """Without damping or friction the die bounces to the time cap: thousands of events a throw (millions at
    t_max 1e5: 32 MB a row, once estimated at 640 bytes).  The calibrating probe counts them (a throw it cut
    short, at the rate it had, to the time cap); the estimate bounds the files written, and holds them in a
    chunk's memory."""
    import dicetrace.scan.estimate as E

    monkeypatch.setattr(E, "SLOWEST_STEP_S", 1.0)  # calibrate this small scan (its time bound says 30 s and more)
    cfg = make_config("physical", gamma=0.0, mu=0.0, t_max_s=300.0)  # 300,000 steps; the probe runs 20,000
    space = Grid("seed", "home", 2)
    defn = ScanDefinition(space, cfg, 2, events=True)
    fixed, est = estimate_scan(defn, calibrate=False), estimate_scan(defn)
    assert fixed.sets_per_ic is None and est.sets_per_ic > 1000
    assert est.bytes > 10 * fixed.bytes and est.chunk_memory > 10 * fixed.chunk_memory
    assert "contact sets per IC on a probe" in est.describe()
    scan(defn, tmp_path / "s")
    df = read_scan(tmp_path / "s")
    sets = df["contact_times_s"].map(len)
    assert (df["status"] == "time_cap").all() and sets.min() > 1000
    assert 0.5 < est.sets_per_ic / sets.mean() < 2  # extrapolated from a fifteenth of the throw
    on_disk = sum(f.stat().st_size for f in (tmp_path / "s" / "rolls").iterdir())
    assert on_disk <= est.bytes  # an upper bound of the real files
    per_event = (on_disk - defn.n_chunks * E.BYTES_PER_CHUNK) / sets.sum()
    assert per_event < E.BYTES_PER_SET_EVENTS, per_event


@pytest.mark.slow
def test_a_scan_of_millions_of_events_says_so_and_what_will_not_fit_is_refused_before_any_work(tmp_path,
                                                                                               dicetrace_cli):
    """The issue's scan: 100 ICs that never settle, events, t_max 1e5 (about 2 million events each): its chunk
    would need tens of GiB, refused in one line naming --chunk and the events counted, nothing written; in chunks
    of one IC the estimate says gigabytes on disk, not 78.5 KiB."""
    args = ["scan", "--preset", "physical", "--window", "home", "--res", "10", "--events", "--set", "gamma=0",
            "--set", "mu=0", "--t-max", "1e5", "--out", "s"]
    res = dicetrace_cli(*args, cwd=tmp_path)
    assert res.returncode == 2, res.stderr
    (line,) = res.stderr.strip().splitlines()
    assert "--chunk" in line and "contact sets per IC on a probe" in line and "GiB of memory" in line, line
    assert not (tmp_path / "s").exists()
    cfg = make_config("physical", gamma=0.0, mu=0.0, t_max_s=1e5)
    est = estimate_scan(ScanDefinition(Grid("seed", "home", 10), cfg, 1, events=True))
    assert est.sets_per_ic > 1e6 and est.bytes > 2**30 and "GiB on disk" in est.describe()


def test_cli_scan_events_and_record_reproduce_the_row(tmp_path, dicetrace_cli):
    out = tmp_path / "ev"
    res = dicetrace_cli("scan", "--preset", "physical", "--window", "home", "--res", "3", "--events", "--out", str(out),
                        "-q", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    row = read_scan(out).iloc[4]
    rec = dicetrace_cli("record", "--scan", str(out), "--at", f"{float(row['x'])!r},{float(row['y'])!r}", "--parquet", "pq",
                        cwd=tmp_path)
    assert rec.returncode == 0, rec.stderr
    assert f"contact_sequence {row['contact_sequence']} " in rec.stdout
    assert "_events.rrd" in rec.stdout
    rolls = pd.read_parquet(tmp_path / "pq" / "rolls.parquet")
    np.testing.assert_array_equal(rolls["contact_times_s"][0], row["contact_times_s"])


@pytest.mark.slow
@pytest.mark.long
def test_dask_runs_an_events_scan_as_a_local_run(events_scan):
    pytest.importorskip("dask.distributed")
    t = scan(GRID, config=PHYSICAL, chunk=4, events=True, dask=True, n_workers=2, device="cpu")
    assert json.loads(t.schema.metadata[b"dicetrace"])["device"] == "cpu"
    from dicetrace.scan.read import read_scan_table

    here = read_scan_table(events_scan)
    assert t.sort_by("ic_id").replace_schema_metadata(None).equals(here.replace_schema_metadata(None))
