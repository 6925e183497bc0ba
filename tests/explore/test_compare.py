"""``/api/compare.rrd`` (dicetrace.explore.compare): the explorer's picked throws in one compare recording."""

from __future__ import annotations

from urllib.parse import urlencode

import numpy as np
import pytest

from explore_helpers import RES, WINDOW


def _throw(i, j, **view):
    q = {"slice": "seed", "window": WINDOW, "res": f"{RES},{RES}", "preset": "seed", **view, "i": i, "j": j}
    return urlencode(q)


def _compare(client, *throws, **extra):
    return client.get("/api/compare.rrd?" + urlencode([("t", t) for t in throws] + list(extra.items())))


@pytest.mark.slow
def test_compare_recording_holds_every_picked_throw(client, tmp_path):
    from dicetrace.sinks.rerun import read_rrd, read_rrd_metadata

    picks = [(3, 12), (12, 4), (8, 8)]
    zoomed = "1.45,1.5,4.0,4.1"  # a throw picked after a zoom: its own view
    throws = [_throw(*picks[0]), _throw(*picks[1]), _throw(*picks[2], window=zoomed)]
    r = _compare(client, *throws)
    assert r.status_code == 200, r.text
    infos = [client.get("/api/hover?" + t).json() for t in throws]
    assert r.headers["x-dicetrace-outcomes"] == ",".join(str(h["outcome"]) for h in infos)
    path = tmp_path / "compare.rrd"
    path.write_bytes(r.content)
    temporal, static = read_rrd(path), read_rrd(path, static=True)
    for k in (1, 2, 3):  # every die, with its path, numbered from 1 as the page numbers its picks
        assert any(e.startswith(f"/throws/{k}/") for e in temporal), sorted(temporal)
    for k in (2, 3):  # the divergence from throw 1 of each other
        assert f"/divergence/distance/{k}" in temporal
    assert "/throws/0/body" not in temporal and "/throws/4/body" not in temporal
    summary = str(static["/summary"].to_pydict())
    for h in infos:  # each throw's grid point, outcome and contact sequence, as the page's hover gave them
        assert f"x = {h['coords']['x']!r}, y = {h['coords']['y']!r}" in summary
        assert h["contact_sequence"] in summary
    meta = read_rrd_metadata(path)
    assert meta["n_throws"] == 3
    np.testing.assert_array_equal(np.asarray(meta["ic"], dtype=float), [infos[0]["ic"][c] for c in ("vx", "vy", "vz", "Lx", "Ly", "Lz")])
    # the download: a file name as record gives a comparison
    d = _compare(client, *throws[:2], download="1")
    assert d.status_code == 200 and 'filename="compare2_seed_x' in d.headers["content-disposition"]


@pytest.mark.parametrize("throws, says", [
    ([_throw(1, 1)], "give 2 to 6 throws"),
    ([_throw(1, 1)] * 7, "give 2 to 6 throws"),
    ([_throw(1, 1), _throw(RES, 1)], f"throw 2: pixel ({RES}, 1) outside its {RES}×{RES} map"),
    ([_throw(1, 1), _throw("a", 1)], "throw 2: its pixel indices i and j must be whole numbers"),
    ([_throw(1, 1), _throw(1, 1, res="abc")], "throw 2: res:"),
    ([_throw(1, 1), _throw(2, 2, gamma="0.5")], "throw 2 has another configuration"),
])
def test_bad_comparisons_get_a_400_naming_the_throw(client, throws, says):
    r = _compare(client, *throws)
    assert r.status_code == 400
    j = r.json()
    assert j["param"] == "t" and says in j["error"], j


def test_a_comparison_past_its_time_is_a_504_naming_t(client, monkeypatch):
    import threading

    from dicetrace.explore import compare

    release = threading.Event()
    monkeypatch.setattr(compare, "COMPARE_TIMEOUT_S", 0.2)
    monkeypatch.setattr(compare, "compare_rrd", lambda throws, activate, aspect=None: release.wait(30))
    try:
        r = _compare(client, _throw(1, 1), _throw(2, 2))
    finally:
        release.set()
    assert r.status_code == 504
    assert r.json()["param"] == "t" and "more than 0.2 s" in r.json()["error"]
