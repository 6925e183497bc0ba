"""The scan's maps (``--png``, ``--rrd``) on a full disk: nothing half-written is kept, the old maps stay whole.

Each map is written to a hidden temporary file beside it, synced and renamed
into place together with the other (both maps or neither); on an error the
temporaries, and any folder made for them, are removed.  A full disk is
simulated by making the writer raise ENOSPC after writing part of the map
(the PNG) or when the data is synced (the recording: where a delayed
allocation reports a full disk).
"""

from __future__ import annotations

import errno
import os

import pytest

from dicetrace.ics import Grid
from dicetrace.scan import scan

HOME3 = ["--window", "home", "--res", "3"]


def _full(*_a, **_k):
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


def _half_a_png(self, fname, *a, **k):
    with open(fname, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n half a map")
    _full()


@pytest.fixture
def scanned(tmp_path):
    """A finished scan folder ``s`` (the command only draws the maps) and old maps in ``maps/``."""
    scan(Grid("seed", "home", 3), tmp_path / "s")
    maps = tmp_path / "maps"
    maps.mkdir()
    (maps / "m.png").write_bytes(b"old map")
    (maps / "m.rrd").write_bytes(b"old scan map")
    return tmp_path


def _listing(folder):
    return {str(p.relative_to(folder)): (p.read_bytes() if p.is_file() else None) for p in sorted(folder.rglob("*"))}


@pytest.mark.parametrize("where", ["png", "rrd"])
def test_a_full_disk_while_writing_a_map_keeps_nothing_half_written(scanned, dicetrace_cli, assert_one_line_error,
                                                                     monkeypatch, where):
    import matplotlib.figure

    maps = scanned / "maps"
    before = _listing(maps)
    scan_before = _listing(scanned / "s")
    if where == "png":
        monkeypatch.setattr(matplotlib.figure.Figure, "savefig", _half_a_png)
    else:
        monkeypatch.setattr(os, "fsync", _full)  # the recording's data reach the disk only when synced
    res = dicetrace_cli("scan", *HOME3, "--out", "s", "--png", str(maps / "m.png"), "--rrd", str(maps / "m.rrd"),
                        "-q", cwd=scanned)
    line = assert_one_line_error(res, "No space left on device")
    assert "m.png" in line or "m.rrd" in line
    assert _listing(maps) == before  # both old maps whole, no temporary
    assert _listing(scanned / "s") == scan_before  # the scan folder as it was


@pytest.mark.parametrize("where", ["png", "rrd"])
def test_a_full_disk_leaves_no_folder_made_for_the_maps(scanned, dicetrace_cli, assert_one_line_error, monkeypatch,
                                                       where):
    import matplotlib.figure

    if where == "png":
        monkeypatch.setattr(matplotlib.figure.Figure, "savefig", _half_a_png)
        opt = ["--png", str(scanned / "new" / "maps" / "m.png")]
    else:
        monkeypatch.setattr(os, "fsync", _full)
        opt = ["--rrd", str(scanned / "new" / "maps" / "m.rrd")]
    res = dicetrace_cli("scan", *HOME3, "--out", "s", *opt, "-q", cwd=scanned)
    assert_one_line_error(res, "No space left on device")
    assert not (scanned / "new").exists()
    assert sorted(p.name for p in scanned.iterdir()) == ["maps", "s"]
