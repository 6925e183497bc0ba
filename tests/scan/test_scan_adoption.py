"""A resume adopts only what it checked: each chunk against the scan it resumes, the chunk log entry by entry.

Reproducers of a hostile trial (issue 47, A1-A6), each on a real scan folder
tampered with as a user (or a tool) could:

* A1: the manifest's definition edited (window, gamma): every chunk's own
  metadata names its scan; the resume compares it and refuses by name.
* A2, A3: a chunk the log does not list (another scan's with its metadata
  stripped, one holding only ``ic_id``) is checked -- columns, ic_ids, grid
  indices, slice coordinates, metadata -- before it is logged.
* A4, A6: a broken chunk-log entry (not an object, rows as a string) lists
  nothing: the chunk is checked by its content and adopted, and the log
  repaired, with one warning.
* A5: a part beside the manifest (read twice by other Parquet readers) is
  refused by name.
* A6: definitions compare by value: ``0`` and ``0.0`` are one number; a
  refusal names the field that differs.

Whatever is refused is one line, exit 2, the folder untouched.
"""

from __future__ import annotations

import json
import shutil
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from dicetrace.ics import Grid
from dicetrace.scan import CorruptChunkError, read_manifest, read_scan, read_scan_table, scan
from dicetrace.scan.definition import describe_differences
from dicetrace.scan.folder import (
    CHUNK_LOG_KEY,
    MANIFEST,
    MANIFEST_KEY,
    ScanWarning,
    _manifest_metadata,
    _write_manifest,
    read_chunk_log,
)
from scan_rows import rows as _data

HOME5 = Grid("seed", "home", 5)
ARGS = ["scan", "--window", "home", "--res", "5", "--chunk", "5", "-q"]


@pytest.fixture(scope="module")
def home5() -> pa.Table:
    return scan(HOME5, chunk=5)


def _edit_definition(folder: Path, edit) -> None:
    """Rewrite the manifest with its definition changed by ``edit(definition)`` (the chunk log kept)."""
    manifest = read_manifest(folder)
    edit(manifest["definition"])
    _write_manifest(folder, manifest, read_chunk_log(folder))


def _set_raw_log(folder: Path, raw: bytes) -> None:
    """Rewrite the manifest's chunk log as the bytes ``raw`` (the definition kept), as a hand edit would."""
    meta = dict(_manifest_metadata(folder / MANIFEST))
    meta[CHUNK_LOG_KEY] = raw
    table = pq.read_table(folder / MANIFEST)
    pq.write_table(table.replace_schema_metadata(meta), folder / MANIFEST)


def _raw_log(folder: Path) -> dict:
    return json.loads(_manifest_metadata(folder / MANIFEST)[CHUNK_LOG_KEY])


def _strip_metadata(src: Path, dst: Path) -> None:
    pq.write_table(pq.read_table(src).replace_schema_metadata(None), dst)


# -- A1: the manifest's definition edited -----------------------------------------------------------------------------


@pytest.mark.parametrize("edit, args, field", [
    (lambda d: d["space"].update(window=[[0.0, 0.2], [0.0, 0.2]]), ["--window", "0,0.2,0,0.2"], "space.window"),
    (lambda d: d["config"]["preset"].update(gamma=0.05), ["--window", "home", "--set", "gamma=0.05"],
     "config.preset.gamma"),
], ids=["window", "gamma"])
def test_a_hand_edited_definition_does_not_adopt_the_old_rows(tmp_path, dicetrace_cli, assert_one_line_error,
                                                              snapshot, edit, args, field):
    out = tmp_path / "s"
    scan(HOME5, out, chunk=5)
    _edit_definition(out, edit)
    before = snapshot(out)
    res = dicetrace_cli("scan", *args, "--res", "5", "--chunk", "5", "--out", str(out), "-q", cwd=tmp_path)
    line = assert_one_line_error(res, "--out", "part-000000.parquet", "another scan", field, "move it out")
    assert "5 more such file(s)" not in line and "4 more such file(s)" in line  # every chunk, the first named
    assert snapshot(out) == before
    with pytest.raises(CorruptChunkError, match=rf"part-000000\.parquet.*{field}"):
        read_scan(out)  # the readers do not serve the old rows under the new definition either


# -- A2, A3: chunks the log does not list -----------------------------------------------------------------------------


def test_another_scans_chunk_with_its_metadata_stripped_is_not_adopted(tmp_path, dicetrace_cli, assert_one_line_error,
                                                                      snapshot, home5):
    out, other = tmp_path / "s", tmp_path / "other"
    scan(HOME5, out, chunk=5, max_chunks=2)
    scan(Grid("seed", "party", 5), other, chunk=5)  # same sizes and ic_ids, another window
    _strip_metadata(other / "rolls" / "part-000002.parquet", out / "rolls" / "part-000002.parquet")
    before = snapshot(out)
    res = dicetrace_cli(*ARGS, "--out", str(out), cwd=tmp_path)
    assert_one_line_error(res, "--out", "part-000002.parquet", "not listed", "slice coordinates are not chunk 2's")
    assert snapshot(out) == before and sorted(read_chunk_log(out)) == [0, 1]
    # the scan's own chunk 2 with its metadata stripped: its content is the chunk's, but no dicetrace chunk lacks it
    scan(HOME5, tmp_path / "mine", chunk=5)
    _strip_metadata(tmp_path / "mine" / "rolls" / "part-000002.parquet", out / "rolls" / "part-000002.parquet")
    assert_one_line_error(dicetrace_cli(*ARGS, "--out", str(out), cwd=tmp_path), "part-000002.parquet",
                          "no dicetrace metadata")
    (out / "rolls" / "part-000002.parquet").unlink()
    assert dicetrace_cli(*ARGS, "--out", str(out), cwd=tmp_path).returncode == 0
    assert _data(read_scan(out)).equals(_data(home5))


def test_a_chunk_of_only_ic_ids_is_refused_by_name_and_never_breaks_the_folder(tmp_path, dicetrace_cli,
                                                                               assert_one_line_error, snapshot, home5):
    out = tmp_path / "s"
    scan(HOME5, out, chunk=5, max_chunks=1)
    bogus = out / "rolls" / "part-000001.parquet"
    pq.write_table(pa.table({"ic_id": np.arange(5, 10, dtype=np.int64)}), bogus)
    before = snapshot(out)
    res = dicetrace_cli(*ARGS, "--out", str(out), cwd=tmp_path)
    assert_one_line_error(res, "--out", "part-000001.parquet", "columns are not the scan's", "missing")
    assert snapshot(out) == before and sorted(read_chunk_log(out)) == [0]

    # a folder an earlier dicetrace broke: the same file adopted into the log (its checksum logged)
    from dicetrace.scan.chunk_files import file_sha256

    digest, size = file_sha256(bogus)
    log = read_chunk_log(out)
    log[1] = {"chunk": 1, "file": "rolls/part-000001.parquet", "rows": 5, "bytes": size, "sha256": digest}
    _write_manifest(out, read_manifest(out), log)
    with pytest.raises(CorruptChunkError, match=r"part-000001\.parquet.*columns are not the scan's"):
        read_scan_table(out)  # not 5 rows of nulls
    at = dicetrace_cli("record", "--scan", str(out), "--at", "0.05,0.05", "--out", str(tmp_path / "r.rrd"),
                       cwd=tmp_path)
    assert_one_line_error(at, "--scan", "part-000001.parquet")
    before = snapshot(out)
    res = dicetrace_cli(*ARGS, "--out", str(out), cwd=tmp_path)  # exit 2 naming it, not 70 (a TypeError)
    assert_one_line_error(res, "--out", "part-000001.parquet", "is listed in", "columns are not the scan's")
    assert snapshot(out) == before
    bogus.unlink()  # as the line says: moved out, its chunk is computed again
    assert dicetrace_cli(*ARGS, "--out", str(out), cwd=tmp_path).returncode == 0
    assert _data(read_scan(out)).equals(_data(home5))


# -- A4, A6: broken chunk-log entries ---------------------------------------------------------------------------------


@pytest.mark.parametrize("entry", [5, "rolls/part-000001.parquet", None, [1, 2]], ids=["int", "str", "null", "list"])
def test_a_chunk_log_entry_that_is_not_an_object_lists_nothing_and_its_chunk_is_adopted(tmp_path, home5, entry):
    out = tmp_path / "s"
    scan(HOME5, out, chunk=5)
    raw = _raw_log(out)
    good = raw["1"]
    raw["1"] = entry
    _set_raw_log(out, json.dumps(raw).encode())
    with pytest.raises(CorruptChunkError, match=r"part-000001\.parquet.*chunk log.*broken"):
        read_scan(out)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        r = scan(HOME5, out, chunk=5)  # an AttributeError once
    assert (r.chunks_skipped, r.chunks_computed) == (5, 0)  # adopted by its content, not recomputed
    said = [str(w.message) for w in caught if issubclass(w.category, ScanWarning)]
    assert len(said) == 1 and "chunk log" in said[0] and "broken" in said[0] and "chunk 1" in said[0]
    assert _raw_log(out)["1"] == good  # the log repaired
    assert _data(read_scan(out)).equals(_data(home5))


def test_a_chunk_log_with_rows_as_a_string_is_repaired_not_refused(tmp_path, dicetrace_cli, home5):
    out = tmp_path / "s"
    scan(HOME5, out, chunk=5)
    raw = _raw_log(out)
    raw["3"]["rows"] = "5"
    _set_raw_log(out, json.dumps(raw).encode())
    res = dicetrace_cli(*ARGS, "--out", str(out), cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    (line,) = res.stderr.strip().splitlines()  # one warning: no "it holds 5 rows, the chunk has 5"
    assert line.startswith("dicetrace: warning: the chunk log") and "rows \"5\"" in line, line
    assert "the chunk has" not in line
    assert _raw_log(out)["3"]["rows"] == 5
    assert _data(read_scan(out)).equals(_data(home5))


@pytest.mark.parametrize("raw", [b"[1, 2]", b"not json", b'{"x": {}}'], ids=["list", "garbage", "key"])
def test_a_chunk_log_that_cannot_be_read_at_all_is_rebuilt_from_the_chunks(tmp_path, home5, raw):
    out = tmp_path / "s"
    scan(HOME5, out, chunk=5)
    _set_raw_log(out, raw)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        r = scan(HOME5, out, chunk=5)
    assert (r.chunks_skipped, r.chunks_computed) == (5, 0)
    assert any(issubclass(w.category, ScanWarning) and "chunk log" in str(w.message) for w in caught)
    assert sorted(read_chunk_log(out)) == [0, 1, 2, 3, 4]
    assert _data(read_scan(out)).equals(_data(home5))


# -- A5: a part beside the manifest ----------------------------------------------------------------------------------


def test_a_stray_part_beside_the_manifest_is_refused_by_name(tmp_path, dicetrace_cli, assert_one_line_error, snapshot,
                                                             home5):
    out = tmp_path / "s"
    scan(HOME5, out, chunk=5)
    shutil.copy(out / "rolls" / "part-000002.parquet", out / "part-000002.parquet")
    assert len(pd.read_parquet(out)) == 30  # what any other reader makes of it: 5 rows twice
    before = snapshot(out)
    res = dicetrace_cli(*ARGS, "--out", str(out), cwd=tmp_path)
    assert_one_line_error(res, "--out", f"'{out / 'part-000002.parquet'}'", "beside", "rolls/")
    assert snapshot(out) == before
    (out / "part-000002.parquet").unlink()
    assert dicetrace_cli(*ARGS, "--out", str(out), cwd=tmp_path).returncode == 0
    assert len(pd.read_parquet(out)) == 25


def test_a_part_an_interrupted_conversion_left_beside_the_manifest_is_still_taken(tmp_path, home5):
    """An older layout's part (beside the manifest) whose move into rolls/ a kill interrupted: the log names it
    there and rolls/ lacks its chunk, so it is the scan's, moved into rolls/ and not recomputed."""
    out = tmp_path / "s"
    scan(HOME5, out, chunk=5)
    (out / "rolls" / "part-000001.parquet").rename(out / "part-000001.parquet")
    log = read_chunk_log(out)
    log[1]["file"] = "part-000001.parquet"
    _write_manifest(out, read_manifest(out), log)
    r = scan(HOME5, out, chunk=5)
    assert (r.chunks_skipped, r.chunks_computed) == (5, 0)
    assert not (out / "part-000001.parquet").exists() and (out / "rolls" / "part-000001.parquet").exists()
    assert _data(read_scan(out)).equals(_data(home5))


# -- A6: definitions compare by value --------------------------------------------------------------------------------


def test_definitions_compare_by_value_and_a_refusal_names_the_field():
    from dicetrace.scan.definition import same_definition

    a = {"space": {"window": [[0, 0.1], [0, 0.1]], "res": [5, 5]}, "chunk": 5, "events": False}
    assert describe_differences(a, {"space": {"window": [[0.0, 0.1], [0.0, 0.1]], "res": [5.0, 5]}, "chunk": 5.0,
                                    "events": False}) == []
    assert describe_differences(a, {**a, "events": 0}) == ["events: false vs 0"]  # a boolean is no number
    assert describe_differences(a, {**a, "chunk": "5"}) == ['chunk: 5 vs "5"']
    assert describe_differences(a, {**a, "space": {"window": [[0, 0.2], [0, 0.1]], "res": [5, 5]}}) == [
        "space.window: [[0, 0.1], [0, 0.1]] vs [[0, 0.2], [0, 0.1]]"]
    assert describe_differences(a, {"chunk": 5}) == ["events: false vs (absent)", 'space: {"window": [[0, 0.1], [0, '
                                                     '0.1]], "res": [5, 5]} vs (absent)']
    assert same_definition({"format": "dicetrace-scan/1", "chunk": 5},
                           {"format": "dicetrace-scan/1", "chunk": 5.0, "device": "cpu", "events": False})


def test_a_definition_written_with_other_numerals_resumes_and_one_that_differs_names_its_field(
        tmp_path, dicetrace_cli, assert_one_line_error, snapshot, home5):
    out = tmp_path / "s"
    scan(HOME5, out, chunk=5, max_chunks=3)
    _edit_definition(out, lambda d: d["space"].update(window=[[0, 0.1], [0, 0.1]]))  # 0 for 0.0: the same window
    res = dicetrace_cli(*ARGS, "--out", str(out), cwd=tmp_path)
    assert res.returncode == 0, res.stderr  # once "holds a different scan ()"
    assert sorted(read_chunk_log(out)) == [0, 1, 2, 3, 4]
    assert _data(read_scan(out)).equals(_data(home5))
    _edit_definition(out, lambda d: d["space"].update(window=[[0, 0.2], [0, 0.1]]))
    before = snapshot(out)
    line = assert_one_line_error(dicetrace_cli(*ARGS, "--out", str(out), cwd=tmp_path), "--out", "different scan",
                                 "space.window: [[0, 0.2], [0, 0.1]] vs [[0.0, 0.1], [0.0, 0.1]]")
    assert "()" not in line
    assert snapshot(out) == before
    assert json.loads(_manifest_metadata(out / MANIFEST)[MANIFEST_KEY])["definition"]["space"]["window"][0] == [0, 0.2]
