"""Scan folders are safe: one writer at a time, checksummed chunks, exact sizes, nothing left by a refusal.

* Concurrent writers: the folder's lock (filelock) makes a second scan wait
  (``wait``) or refuse in one line, touching nothing of the first, not even
  its in-progress temporary file; two real concurrent scans end cleanly with
  a dataset bit-identical to a single run.
* Corruption: a chunk damaged after it was written (footer intact) is
  recomputed on resume (with a warning naming it) and named by ``read_scan``.
* Sizes: exact Python ints, refused beyond what a scan can number.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest

from dicetrace.ics import Grid, Points, Sample
from dicetrace.params import make_config
from dicetrace.scan import MANIFEST, ScanDefinition, ScanMismatchError, read_manifest, read_scan, scan
from dicetrace.scan.read import label_grid, outcome_counts, status_counts
from dicetrace.scan.folder import (
    CHUNK_LOG_KEY,
    LEGACY_CHUNK_LOG,
    LEGACY_MANIFEST,
    LOCK,
    CorruptChunkError,
    ScanBusyError,
    ScanWarning,
    read_chunk_log,
)
from scan_rows import rows as _data

HOME5 = Grid("seed", "home", 5)


@pytest.fixture(scope="module")
def home5() -> pa.Table:
    return scan(HOME5, chunk=5)


def _flip_middle(path: Path) -> None:
    """Flip bytes in the middle of a Parquet file (the footer stays intact: the file still opens)."""
    b = bytearray(path.read_bytes())
    i = len(b) // 2
    for k in range(i, i + 8):
        b[k] ^= 0xFF
    path.write_bytes(bytes(b))


# -- one writer at a time --------------------------------------------------------------------------------------


def _hold_lock(folder: Path):
    """Hold the folder's writer lock as a running scan would (a separate lock: flock conflicts within a process too)."""
    from filelock import FileLock

    lock = FileLock(str(folder / LOCK), thread_local=False)  # released by a timer thread below
    lock.acquire(timeout=0)
    return lock


def test_a_second_writer_refuses_at_once_and_touches_nothing(tmp_path):
    out = tmp_path / "s"
    r = scan(HOME5, out, chunk=5, max_chunks=2)
    assert r.chunks_computed == 2
    in_progress = out / ".part-000002.parquet.4242-running.tmp"  # the running scan's chunk being written
    in_progress.write_bytes(b"PAR1 half written")
    before = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    lock = _hold_lock(out)
    try:
        t0 = time.monotonic()
        with pytest.raises(ScanBusyError, match=r"another dicetrace scan is writing into .*waited 0 s"):
            scan(HOME5, out, chunk=5)
        with pytest.raises(ScanBusyError, match="waited 0.4 s"):
            scan(HOME5, out, chunk=5, wait=0.4)
        assert 0.35 < time.monotonic() - t0 < 5
        assert {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()} == before  # the running scan's files untouched
    finally:
        lock.release()
    r = scan(HOME5, out, chunk=5, wait=1.0)  # the first is gone: its temporary is a leftover now, and removed
    assert (r.chunks_skipped, r.chunks_computed) == (2, 3) and not in_progress.exists()


def test_the_cli_waits_for_the_writer_then_resumes(tmp_path, dicetrace_cli, assert_one_line_error):
    import threading

    out = tmp_path / "s"
    args = ["scan", "--window", "home", "--res", "5", "--chunk", "5", "--out", str(out), "-q"]
    scan(HOME5, out, chunk=5, max_chunks=1)
    lock = _hold_lock(out)
    try:
        assert_one_line_error(dicetrace_cli(*args, cwd=tmp_path), "--wait", "another dicetrace scan", f"'{out}'")
    finally:
        timer = threading.Timer(0.5, lock.release)  # the "other scan" ends half a second into our wait
        timer.start()
    res = dicetrace_cli(*args, "--wait", "30", cwd=tmp_path)
    timer.join()
    assert res.returncode == 0, res.stderr
    assert len(read_scan(out)) == 25


def test_a_refusal_leaves_no_lock_file_in_a_folder_it_did_not_make(tmp_path):
    other = tmp_path / "notascan"
    other.mkdir()
    (other / "notes.txt").write_text("mine")
    with pytest.raises(FileExistsError):
        scan(HOME5, other)
    assert sorted(p.name for p in other.iterdir()) == ["notes.txt"]
    with pytest.raises(ValueError, match="max_chunks"):
        scan(HOME5, tmp_path / "new", max_chunks=-1)
    assert not (tmp_path / "new").exists()


def test_a_scan_refused_busy_removes_nothing_of_the_holder_and_one_that_fails_first_leaves_nothing(tmp_path,
                                                                                                     monkeypatch):
    import os

    from dicetrace.scan import folder as folder_mod

    out = tmp_path / "new" / "s"
    out.mkdir(parents=True)  # the holder made it, and holds its lock before writing anything
    lock = _hold_lock(out)
    inode = os.stat(out / LOCK).st_ino
    try:
        with pytest.raises(ScanBusyError):
            scan(Grid("seed", "home", 3), out, chunk=4)
        assert sorted(p.name for p in out.iterdir()) == [LOCK] and os.stat(out / LOCK).st_ino == inode
    finally:
        lock.release()

    def full(*a, **k):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(folder_mod, "_write_manifest", full)  # fails while holding the lock, before any manifest
    with pytest.raises(OSError):
        scan(Grid("seed", "home", 3), tmp_path / "made" / "s", chunk=4)
    assert not (tmp_path / "made").exists()


def _cli_scan(out: Path, res: str):
    return subprocess.Popen(
        [sys.executable, "-m", "dicetrace.cli", "scan", "--window", "0,1,0,1", "--res", res, "--chunk", "40",
         "--threads", "1", "--dt", "5e-4", "--out", str(out), "-q", "--wait", "300"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )


@pytest.mark.slow
@pytest.mark.long
def test_two_concurrent_scans_end_cleanly_with_the_single_run_dataset(tmp_path):
    """Same definition twice at once: one computes, the other waits and finds it done; both exit 0.
    Another definition meanwhile: refused in one line (exit 2).  The dataset is bit-identical to a single run."""
    out = tmp_path / "s"
    a, b = _cli_scan(out, "20"), _cli_scan(out, "20")
    while not (out / MANIFEST).exists() and a.poll() is None and b.poll() is None:
        time.sleep(0.02)
    with pytest.raises(ScanMismatchError, match="different scan"):  # another definition, meanwhile: refused at once
        scan(Grid("seed", ((0.0, 1.0), (0.0, 1.0)), 21), out, chunk=40, dt_s=5e-4)
    results = [p.communicate(timeout=300) + (p.returncode,) for p in (a, b)]
    (_, ea, ra), (_, eb, rb) = results
    assert (ra, rb) == (0, 0), (ea, eb)
    assert "Traceback" not in ea + eb
    df = read_scan(out)
    assert (df["ic_id"] == np.arange(400)).all()
    want = scan(Grid("seed", ((0.0, 1.0), (0.0, 1.0)), 20), chunk=400, dt_s=5e-4)
    assert _data(df).equals(_data(want))
    assert not list(out.glob(".*.tmp"))


# -- two scans of different definitions racing for a new folder ------------------------------------------------------

#: A scan process for many races: imports and loads what a scan needs, says "ready", then for each folder named on
#: stdin runs ``dicetrace ARGS --out FOLDER`` and answers its exit code and standard error (JSON, one line).  Two
#: such processes given the same folder at once reach it within a millisecond or so of each other.
_RACER = r"""
import contextlib, io, json, sys
from dicetrace.cli import app
from dicetrace.commands._common import run_app
args = sys.argv[1:]
print("ready", flush=True)
for line in sys.stdin:
    err = io.StringIO()
    sys.argv = ["dicetrace", *args, "--out", line.strip()]
    with contextlib.redirect_stderr(err):
        try:
            run_app(app)
            rc = 0
        except SystemExit as e:
            rc = e.code or 0
    print(json.dumps({"rc": rc, "err": err.getvalue()}), flush=True)
"""


def _racer(res: str):
    return subprocess.Popen(
        [sys.executable, "-c", _RACER, "scan", "--window", "home", "--res", res, "--chunk", "4", "--threads", "1",
         "-q"],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )


def _answer(p, timeout: float = 120.0) -> dict:
    """The racer's next answer, or a failure when none comes within ``timeout`` seconds."""
    import selectors

    with selectors.DefaultSelector() as sel:
        sel.register(p.stdout, selectors.EVENT_READ)
        if not sel.select(timeout):
            pytest.fail(f"a racing scan did not answer within {timeout:g} s")
    line = p.stdout.readline()
    assert line, p.stderr.read()
    return json.loads(line) if line.strip() != "ready" else {"ready": True}


@pytest.mark.slow
@pytest.mark.long
def test_two_scans_of_different_definitions_racing_for_a_new_folder_one_wins_the_other_refuses(tmp_path):
    """20 races of two real scan processes (3x3 and 4x4 grids) released together on a new folder each time: exactly
    one completes a valid folder (its lock still in place), the other exits 2 in one line (busy, or a different scan)
    and removes nothing of the winner's."""
    procs = {"3": _racer("3"), "4": _racer("4")}
    try:
        for p in procs.values():
            assert _answer(p) == {"ready": True}
        for race in range(20):
            out = tmp_path / f"race{race}" / "s"
            for p in procs.values():  # the folder and its parent do not exist yet
                p.stdin.write(f"{out}\n")
                p.stdin.flush()
            results = {res: _answer(p) for res, p in procs.items()}
            assert sorted(r["rc"] for r in results.values()) == [0, 2], (race, results)
            winner = next(res for res, r in results.items() if r["rc"] == 0)
            err = next(r["err"] for r in results.values() if r["rc"] == 2)
            lines = err.strip().splitlines()
            assert len(lines) == 1 and lines[0].startswith("dicetrace: error: "), (race, err)
            assert "another dicetrace scan is writing" in err or "holds a different scan" in err, (race, err)
            assert sorted(p.name for p in out.iterdir()) == [LOCK, MANIFEST, "rolls"], (race, results)  # lock stays
            assert read_manifest(out)["definition"]["space"]["res"] == [int(winner)] * 2
            assert (read_scan(out)["ic_id"] == np.arange(int(winner) ** 2)).all(), race
    finally:
        for p in procs.values():
            p.stdin.close()
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()

# -- checksums -------------------------------------------------------------------------------------------------------


def test_each_chunk_is_logged_with_its_checksum(tmp_path):
    import hashlib

    out = tmp_path / "s"
    scan(HOME5, out, chunk=10)
    log = read_chunk_log(out)
    assert sorted(log) == [0, 1, 2]
    for c, e in log.items():
        p = out / e["file"]
        assert e["sha256"] == hashlib.sha256(p.read_bytes()).hexdigest() and e["bytes"] == p.stat().st_size
        assert e["rows"] == (10 if c < 2 else 5)
    import pyarrow.parquet as pq

    meta = pq.read_schema(out / MANIFEST).metadata  # the log lives in the manifest's metadata
    assert sorted(json.loads(meta[CHUNK_LOG_KEY])) == ["0", "1", "2"]


def test_the_chunk_log_is_rewritten_at_most_once_a_second_and_complete_at_the_end(tmp_path, monkeypatch):
    """25 chunks in well under a second: the manifest is written when the folder is made, for the first chunk and
    as the scan ends -- not once per chunk (its log grows with the chunks) -- and logs every chunk."""
    from dicetrace.scan import folder as folder_mod

    writes = []
    real = folder_mod._write_manifest
    monkeypatch.setattr(folder_mod, "_write_manifest", lambda f, m, log: (writes.append(len(log)), real(f, m, log)))
    monkeypatch.setattr(folder_mod, "LOG_INTERVAL_S", 60.0)
    out = tmp_path / "s"
    scan(HOME5, out, chunk=1)
    assert writes == [0, 1, 25]
    assert sorted(read_chunk_log(out)) == list(range(25))


def test_a_corrupted_chunk_is_named_on_read_and_recomputed_on_resume(tmp_path, home5):
    out = tmp_path / "s"
    scan(HOME5, out, chunk=5)
    bad = out / "rolls" / "part-000002.parquet"
    _flip_middle(bad)
    for reader in (read_scan, label_grid, outcome_counts, status_counts):
        with pytest.raises(CorruptChunkError, match=r"part-000002\.parquet.*SHA-256"):
            reader(out)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        r = scan(HOME5, out, chunk=5)
    assert (r.chunks_skipped, r.chunks_computed) == (4, 1)
    msgs = [str(w.message) for w in caught if issubclass(w.category, ScanWarning)]
    assert len(msgs) == 1 and "part-000002.parquet" in msgs[0] and "recomputing" in msgs[0]
    assert _data(read_scan(out)).equals(_data(home5))  # bit-identical again


def test_the_cli_says_it_recomputes_a_damaged_chunk(tmp_path, dicetrace_cli, home5):
    out = tmp_path / "s"
    scan(HOME5, out, chunk=5)
    _flip_middle(out / "rolls" / "part-000000.parquet")
    args = ["scan", "--window", "home", "--res", "5", "--chunk", "5", "--out", str(out), "-q"]
    res = dicetrace_cli(*args, cwd=tmp_path)
    assert res.returncode == 0
    (line,) = res.stderr.strip().splitlines()
    assert line.startswith("dicetrace: warning: scan chunk") and "part-000000.parquet" in line
    assert _data(read_scan(out)).equals(_data(home5))
    res = dicetrace_cli("record", "--scan", str(out), "--at", "0.05,0.05", "--out", str(tmp_path / "r.rrd"), cwd=tmp_path)
    assert res.returncode == 0, res.stderr


def test_record_from_a_corrupted_scan_names_the_chunk(tmp_path, dicetrace_cli, assert_one_line_error):
    out = tmp_path / "s"
    scan(HOME5, out, chunk=5)
    _flip_middle(out / "rolls" / "part-000001.parquet")
    res = dicetrace_cli("record", "--scan", str(out), "--at", "0.05,0.05", "--out", str(tmp_path / "r.rrd"), cwd=tmp_path)
    assert_one_line_error(res, "--scan", "part-000001.parquet", "damaged")
    assert not (tmp_path / "r.rrd").exists()


def test_a_folder_without_a_chunk_log_is_adopted_and_garbage_is_refused(tmp_path, home5, to_legacy_layout):
    """Folders written before checksums: whole chunks are adopted (logged), undecodable ones recomputed."""
    out = tmp_path / "s"
    scan(HOME5, out, chunk=5)
    to_legacy_layout(out, chunk_log=False)
    (out / "rolls" / "part-000003.parquet").write_bytes(b"PAR1 this is no Parquet file PAR1")
    with pytest.raises(CorruptChunkError, match=r"part-000003\.parquet"):
        read_scan(out)  # no checksum to compare: the decoding error names the file
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        r = scan(HOME5, out, chunk=5)
    assert (r.chunks_skipped, r.chunks_computed) == (4, 1)
    assert any("part-000003.parquet" in str(w.message) for w in caught)
    assert sorted(read_chunk_log(out)) == [0, 1, 2, 3, 4]
    assert sorted(p.name for p in out.iterdir()) == sorted([LOCK, MANIFEST, "rolls"])  # the JSON manifest converted
    assert _data(read_scan(out)).equals(_data(home5))


def test_a_torn_chunk_log_line_is_ignored(tmp_path, home5, to_legacy_layout):
    """An older dicetrace's append-only chunk log ``_scan.chunks.jsonl`` with a torn last line."""
    out = tmp_path / "s"
    scan(HOME5, out, chunk=5, max_chunks=3)
    to_legacy_layout(out)
    with open(out / LEGACY_CHUNK_LOG, "a") as f:
        f.write('{"chunk": 3, "file": "part-0000')  # a write killed half way
    assert sorted(read_chunk_log(out)) == [0, 1, 2]
    r = scan(HOME5, out, chunk=5)
    assert (r.chunks_skipped, r.chunks_computed) == (3, 2)
    assert not (out / LEGACY_MANIFEST).exists() and not (out / LEGACY_CHUNK_LOG).exists()
    assert sorted(read_chunk_log(out)) == [0, 1, 2, 3, 4]
    assert _data(read_scan(out)).equals(_data(home5))



# -- the folder holds what its manifest lists ------------------------------------------------------------------------


def _tree(folder: Path) -> dict:
    return {str(p.relative_to(folder)): (p.read_bytes() if p.is_file() else "dir") for p in sorted(folder.rglob("*"))}


def test_a_copy_of_a_chunk_under_another_name_is_not_read_and_refused_by_name(tmp_path, dicetrace_cli, home5,
                                                                            assert_one_line_error):
    import shutil

    out = tmp_path / "s"
    args = ["scan", "--window", "home", "--res", "5", "--chunk", "5", "--out", str(out), "-q"]
    scan(HOME5, out, chunk=5, max_chunks=2)
    rolls = out / "rolls"
    shutil.copy(rolls / "part-000000.parquet", rolls / "part-000003.parquet")  # a chunk index the scan has not done
    df = read_scan(out)
    assert (df["ic_id"] == np.arange(10)).all()  # only the manifest's files are read: no duplicate ic_id
    assert outcome_counts(out) and sum(status_counts(out).values()) == 10
    before = _tree(out)
    assert_one_line_error(dicetrace_cli(*args, cwd=tmp_path), "--out", "part-000003.parquet", "not listed",
                          "ic_ids are not chunk 3")
    assert _tree(out) == before  # refused by name: nothing moved, deleted or written
    (rolls / "part-000003.parquet").rename(rolls / "part-000099.parquet")  # beyond the scan's chunks
    assert_one_line_error(dicetrace_cli(*args, cwd=tmp_path), "--out", "part-000099.parquet", "beyond")
    (rolls / "part-000099.parquet").rename(tmp_path / "moved-out.parquet")
    (rolls / "notes.txt").write_text("mine")
    with pytest.raises(FileExistsError, match=r"notes\.txt.*none of the scan's chunk files"):
        scan(HOME5, out, chunk=5)
    (rolls / "notes.txt").unlink()
    res = dicetrace_cli(*args, cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert _data(read_scan(out)).equals(_data(home5))


def test_a_folder_where_a_chunk_file_should_be_is_named_by_readers_and_refused_by_a_resume(tmp_path, dicetrace_cli,
                                                                                        assert_one_line_error):
    out = tmp_path / "s"
    args = ["scan", "--window", "home", "--res", "5", "--chunk", "5", "--out", str(out), "-q"]
    scan(HOME5, out, chunk=5)
    part = out / "rolls" / "part-000001.parquet"
    part.unlink()
    part.mkdir()
    (part / "x.parquet").write_bytes(b"mine")
    with pytest.raises(CorruptChunkError, match=r"part-000001\.parquet.*damaged"):
        read_scan(out)
    before = _tree(out)
    assert_one_line_error(dicetrace_cli(*args, cwd=tmp_path), "--out", "part-000001.parquet", "is a folder")
    assert _tree(out) == before


def test_a_resume_adopts_its_own_chunk_that_the_log_missed_and_readers_wait_for_it(tmp_path, home5):
    """A kill between a chunk's rename and the log's next rewrite: the part is the scan's own, not listed yet."""
    from dicetrace.scan.folder import _write_manifest

    out = tmp_path / "s"
    scan(HOME5, out, chunk=5, max_chunks=3)
    log = read_chunk_log(out)
    del log[2]
    _write_manifest(out, read_manifest(out), log)
    assert len(read_scan(out)) == 10  # not listed: not read
    r = scan(HOME5, out, chunk=5)
    assert (r.chunks_skipped, r.chunks_computed) == (3, 2)  # adopted (its content checked), not recomputed
    assert sorted(read_chunk_log(out)) == [0, 1, 2, 3, 4]
    assert _data(read_scan(out)).equals(_data(home5))

# -- sizes ---------------------------------------------------------------------------------------------------------


def test_sizes_are_exact_and_refused_beyond_what_a_scan_can_number():
    assert Grid("seed", "home", 10**10).size == 10**20
    assert Grid("seed3", ((0, 1), (0, 1), (0, 1)), (3000, 3000, 3000)).size == 27 * 10**9
    cfg = make_config()
    with pytest.raises(ValueError, match="100,000,000,000,000,000,000 ICs.*int64"):
        ScanDefinition(Grid("seed", "home", 10**10), cfg)
    with pytest.raises(ValueError, match="int32"):
        ScanDefinition(Grid("seed", "home", (2**31, 1)), cfg)
    d = ScanDefinition(Grid("seed", "home", 10**5), cfg)
    assert (d.size, d.n_chunks) == (10**10, -(-(10**10) // 8192))
    assert isinstance(d.size, int) and d.chunk_range(d.n_chunks - 1)[1] == 10**10
    with pytest.raises(ValueError, match="2\\*\\*30"):
        Sample("seed", "home", 2**30 + 1, "sobol")
    assert Sample("seed", "home", 2**40, "random").size == 2**40


def test_a_huge_scan_folder_is_prepared_without_visiting_every_chunk(tmp_path):
    """10¹⁰ ICs (1.2·10⁶ chunks): max_chunks=0 writes the manifest and returns at once (no loop over all chunks)."""
    t0 = time.perf_counter()
    r = scan(Grid("seed", "home", 10**5), tmp_path / "s", max_chunks=0)
    assert time.perf_counter() - t0 < 5
    man = read_manifest(tmp_path / "s")
    assert man["n_ics"] == 10**10 and r.chunks_computed == 0 and not r.complete


def test_a_scan_of_points_that_overflow_is_refused_before_writing(tmp_path):
    with pytest.raises(ValueError, match="non-finite ICs"):
        scan(Points("seed", [(0.05, 0.05), (1e308, 1e308)]), tmp_path / "s")
    assert not (tmp_path / "s").exists()


def test_a_folder_another_scan_is_making_is_busy_not_foreign(tmp_path, dicetrace_cli, assert_one_line_error):
    """A new folder that another scan holds the lock of and has begun to fill, before its manifest: the scan
    that comes second says the other scan is writing there (it used to call the folder 'not a dicetrace scan',
    in the race of two scans for one new folder), and touches nothing."""
    out = tmp_path / "s"
    (out / "rolls").mkdir(parents=True)
    lock = _hold_lock(out)
    try:
        before = sorted(p.name for p in out.iterdir())
        res = dicetrace_cli("scan", "--window", "home", "--res", "5", "--out", str(out), "-q", cwd=tmp_path)
        assert_one_line_error(res, "--out", "another dicetrace scan is writing", f"'{out}'")
        assert sorted(p.name for p in out.iterdir()) == before
    finally:
        lock.release()
    # with the lock free, the same leftovers are what they are: not a scan
    res = dicetrace_cli("scan", "--window", "home", "--res", "5", "--out", str(out), "-q", cwd=tmp_path)
    assert_one_line_error(res, "--out", "holds no dicetrace scan")
